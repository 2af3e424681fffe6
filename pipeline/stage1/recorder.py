"""Per-step recording of one episode: the flattened states and the step log.

Inputs: a `SimEnv` at the episode's first policy step (after settle), then one
`on_step(StepInfo)` call per control step (from `pipeline.rollout.run_episode`).
Outputs (`write`): `states.npy` (steps+1, state_dim) float64, `actions.npy` (steps, 7)
float64 and `steps.parquet` (`STEP_SCHEMA`), each written atomically. `actions.npy` holds
the actions exactly as the simulator stepped them, so they replay bit for bit (the step
log's float32 `action` column is the same values rounded; rounding before stepping instead
would change every stage-1 rollout of a float64 policy).

Invariants: states row t is the state *before* action t and the last row is the final
state; step-log row t holds action t, the end-effector pose and gripper qpos of state t,
whether the goal held after the step, and whether a new chunk was queried at step t.
Recording reads the simulator only (a copy of ~100 floats per step), never renders.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic import write_with
from pipeline.layout import EpisodeFiles
from pipeline.records import STEP_SCHEMA
from pipeline.rollout import StepInfo
from pipeline.sim import SimEnv
from pipeline.sim.rotations import mat_to_quat


class EpisodeRecorder:
    def __init__(self, env: SimEnv):
        self.env = env
        self.states: list[np.ndarray] = []
        self.eef_pos: list[np.ndarray] = []
        self.eef_quat: list[np.ndarray] = []
        self.gripper: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.goal: list[bool] = []
        self.query: list[bool] = []
        self._snapshot()

    def _snapshot(self) -> None:
        pos, rot = self.env.eef_pose()
        self.states.append(self.env.get_state())
        self.eef_pos.append(pos)
        self.eef_quat.append(mat_to_quat(rot))
        self.gripper.append(self.env.gripper_qpos())

    def on_step(self, info: StepInfo) -> None:
        if info.step != len(self.actions):
            raise RuntimeError(f"recorder got step {info.step}, expected {len(self.actions)}")
        self.actions.append(np.asarray(info.action, dtype=np.float64).copy())
        self.goal.append(bool(info.goal))
        self.query.append(bool(info.query))
        self._snapshot()

    @property
    def steps(self) -> int:
        return len(self.actions)

    def states_array(self) -> np.ndarray:
        return np.stack(self.states)

    def actions_array(self) -> np.ndarray:
        return np.asarray(self.actions, dtype=np.float64).reshape(self.steps, 7)

    def table(self) -> pa.Table:
        n = self.steps

        def fixed(rows: list[np.ndarray], width: int) -> pa.FixedSizeListArray:
            flat = np.asarray(rows[:n], dtype=np.float32).reshape(n * width)
            return pa.FixedSizeListArray.from_arrays(pa.array(flat, pa.float32()), width)

        return pa.Table.from_arrays(
            [
                pa.array(np.arange(n, dtype=np.int32)),
                fixed(self.actions, 7),
                fixed(self.eef_pos, 3),
                fixed(self.eef_quat, 4),
                fixed(self.gripper, 2),
                pa.array(self.goal, pa.bool_()),
                pa.array(self.query, pa.bool_()),
            ],
            schema=STEP_SCHEMA,
        )

    def write(self, folder: str | Path) -> None:
        files = EpisodeFiles(Path(folder))
        states = self.states_array()
        write_with(files.states, lambda p: np.save(p, states))
        actions = self.actions_array()
        write_with(files.actions, lambda p: np.save(p, actions))
        table = self.table()
        write_with(files.steps, lambda p: pq.write_table(table, p))
