"""Geometric reading of a live LIBERO scene for the scripted expert's planner.

Input: a `pipeline.sim.SimEnv` (privileged state). Output: plain numbers the planner
needs: object boxes and footprints, the height of whatever supports a footprint, a safe
travel height along a path, and whether the gripper holds an object. Nothing here moves
the robot; every call reads the current state, so plans made from it are live.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.sim.facts import Box

if TYPE_CHECKING:
    from pipeline.sim import SimEnv

TABLE_MARGIN = 0.012  # fingertips sit ~1 cm below the grip site; keep them off the table
GRIPPER_OPEN = 0.075  # finger-joint spread above which the gripper counts as open
# below this spread the fingers closed on nothing (measured ~0.002); a black bowl's thin
# rim held firmly reads 0.004-0.005, so the old 0.004 flickered to "dropped" mid-carry
CLOSED_EMPTY = 0.003


__all__ = ["Box", "Scene", "robot_base"]


class Scene:
    """Read-only geometric queries over a SimEnv."""

    def __init__(self, env: SimEnv):
        self.env = env

    # ---- objects -------------------------------------------------------------------------
    def box(self, name: str) -> Box:
        lo, hi = self.env.object_aabb(name)
        return Box(lo, hi)

    def pos(self, name: str) -> np.ndarray:
        if self.env.is_region(name):
            return self.env.region(name).pos
        return self.env.object_pose(name)[0]

    def things(self) -> list[str]:
        return self.env.object_names + self.env.fixture_names

    def obstacle_boxes(self, exclude: set[str]) -> list[tuple[str, np.ndarray]]:
        """Every collision box of every object/fixture not in `exclude`, with its owner."""
        out = []
        for name in self.things():
            if name in exclude:
                continue
            try:
                boxes = self.env.object_boxes(name)
            except KeyError:
                continue
            out.extend((name, b) for b in boxes)
        return out

    def support_top(self, xy: np.ndarray, radius: float, exclude: set[str], below: float = np.inf) -> float:
        """Highest top (under `below`) of boxes overlapping a square footprint at `xy`."""
        top = self.table_height()
        for _, b in self.obstacle_boxes(exclude):
            if b[1, 2] >= below:
                continue
            if np.all(b[0, :2] <= xy + radius) and np.all(b[1, :2] >= xy - radius):
                top = max(top, float(b[1, 2]))
        return top

    def path_clearance(self, a: np.ndarray, b: np.ndarray, radius: float, exclude: set[str]) -> float:
        """Highest top of boxes that a footprint of `radius` sweeps over from xy `a` to `b`."""
        top = self.table_height()
        boxes = self.obstacle_boxes(exclude)
        for t in np.linspace(0.0, 1.0, 12):
            xy = (1 - t) * a[:2] + t * b[:2]
            for _, box in boxes:
                if np.all(box[0, :2] <= xy + radius) and np.all(box[1, :2] >= xy - radius):
                    top = max(top, float(box[1, 2]))
        return top

    def table_height(self) -> float:
        # every LIBERO arena's table top sits at the lowest object's resting height
        if not hasattr(self, "_table"):
            lows = [self.env.object_aabb(n)[0][2] for n in self.env.object_names]
            try:  # an object that fell off the table must not lower it (a failure scene)
                top = float(self.env.object_boxes("table")[:, 1, 2].max())
                lows = [z for z in lows if z > top - 0.05] or [top]
            except (KeyError, ValueError):
                pass
            self._table = float(min(lows)) if lows else 0.9
        return self._table

    # ---- robot ---------------------------------------------------------------------------
    def eef(self) -> np.ndarray:
        return self.env.eef_pose()[0]

    def gripper_open(self) -> bool:
        return self.env.gripper_opening() > GRIPPER_OPEN

    def holding(self, name: str) -> bool:
        """The fingers touch `name` and have not closed on nothing."""
        if self.env.gripper_opening() < CLOSED_EMPTY:
            return False
        return tuple(sorted(("robot", name))) in self.env.contacts()

    def holding_any(self) -> str | None:
        if self.env.gripper_opening() < CLOSED_EMPTY:
            return None
        for a, b in self.env.contacts():
            other = b if a == "robot" else a if b == "robot" else None
            if other in self.env.object_names:
                return other
        return None

    def satisfied(self, conjunct: tuple[str, ...]) -> bool:
        return dict(self.env.goal_conjuncts()).get(tuple(conjunct), False)


def robot_base(scene: Scene) -> np.ndarray:
    """World position of the robot's base (both experts measure reach from it)."""
    return scene.env.robot_base()
