"""Tiny synthetic `Evidence` for rule unit tests (no simulator): every object rests, the
gripper is open, nothing touches, unless a test says otherwise."""

from __future__ import annotations

import numpy as np

from pipeline.evidence import Evidence, goal_roles

COLUMNS = ("displacement", "lift", "tilt_deg", "speed", "eef_distance")


def make_evidence(n: int = 60, objects=("bowl_1", "cup_1"), goal=(("on", "bowl_1", "plate_1"),),
                  fixtures=("plate_1",)) -> Evidence:
    objects = list(objects)
    targets, refs = goal_roles([list(g) for g in goal], objects + list(fixtures))
    per = {c: {o: np.zeros(n, dtype=np.float32) for o in objects} for c in COLUMNS}
    for o in objects:
        per["eef_distance"][o][:] = 0.5
    per["position"] = {o: np.zeros((n, 3), dtype=np.float32) for o in objects}
    return Evidence(step=np.arange(n), control_hz=20, gripper_opening=np.full(n, 0.08, np.float32),
                    gripper_command=np.full(n, -1.0, np.float32), grasped=[""] * n, contacts=[[] for _ in range(n)],
                    goal_progress=np.zeros(n, np.float32), objects=objects, fixtures=list(fixtures),
                    goal=[list(g) for g in goal], targets=targets, references=refs, per_object=per)
