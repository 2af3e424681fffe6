"""A tiny privileged waypoint policy for test fixtures: reach points, open/close, wait.

Plans are lists of steps evaluated against the live simulator (`obs.sim`), so they work
from any init state: ("move", object, offset_xyz, gripper), ("hold", gripper, n_steps).
A move ends when the grip site is within 1 cm of the goal or after `max_steps`.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.base import Observation


class WaypointPolicy:
    cameras: tuple[str, ...] = ()
    image_size = 224

    def __init__(self, name: str, plan: list[tuple], gain: float = 8.0, max_steps: int = 60):
        self.name = name
        self.plan = plan
        self.gain = gain
        self.max_steps = max_steps
        self.log: list[tuple[int, str]] = []  # (step, plan item label) when each item starts

    def reset(self, task, seed: int) -> None:
        self._i, self._n, self._goal = 0, 0, None
        self.log = []

    def params(self) -> dict:
        return {"plan": [list(map(str, p)) for p in self.plan]}

    def close(self) -> None:
        pass

    def act(self, obs: Observation) -> np.ndarray:
        a = np.zeros((1, 7))
        while self._i < len(self.plan):
            item = self.plan[self._i]
            if self._n == 0:
                self.log.append((obs.step, f"{self._i}:{item[0]}"))
                if item[0] == "move":
                    pos, _ = obs.sim.object_pose(item[1])
                    self._goal = pos + np.asarray(item[2])
            if item[0] == "hold":
                if self._n < item[2]:
                    self._n += 1
                    a[0, 6] = item[1]
                    return a
            else:
                err = self._goal - obs.eef_pos
                if np.linalg.norm(err) > 0.01 and self._n < self.max_steps:
                    self._n += 1
                    a[0, :3] = np.clip(err * self.gain, -1, 1)
                    a[0, 6] = item[3]
                    return a
            self._i, self._n = self._i + 1, 0
        a[0, 6] = self.plan[-1][1] if self.plan and self.plan[-1][0] == "hold" else -1.0
        return a
