"""The `simstate` localizer: the failure onset from simulator evidence alone (no model).

Input: an episode's `Evidence`. Output: a `SimstateResult`: every event the rules of
`pipeline.labelers.simstate.events` found, the onset (the earliest failure event's step, or None when
no rule fired) and a fallback step for reviewers when there is no onset.

Rules (details and thresholds in events.py): grasp attempted near an object and not
achieved (grasp_missed), grasp lost while still closed (grasp_lost), object released
unsupported and falling (object_dropped), a target let go and set down without goal
progress (object_misplaced), object toppled (object_toppled), an object moved
without having been grasped (unintended_displacement), robot contact with an object or
fixture the goal does not involve (robot_contact_non_target), a held object hitting
something (object_collision), a drawer or knob worked and let go without goal progress
(part_not_operated), goal progress falling back (goal_regression).

Onset = the earliest of these events: each one is task-relevant by construction (it
changes the target, the scene the task needs, or the progress toward the goal). Ties are
broken by the order above, which is the order of `ONSET_PRIORITY`.

Fallback (no event): the step from which the robot stopped changing anything (gripper
command, object positions, grip-site distances all constant), i.e. the episode timed out
idle; the runner quarantines such an episode with reason `no_failure_found` and this step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.evidence import Evidence
from pipeline.labelers.simstate.events import Thresholds, detect_events
from pipeline.records import EventKind, SimEvent

ONSET_PRIORITY = (
    "grasp_missed", "grasp_lost", "object_dropped", "object_misplaced", "object_toppled", "unintended_displacement",
    "robot_contact_non_target", "object_collision", "part_not_operated", "goal_regression",
)
IDLE_TOL_M = 0.002


@dataclass
class SimstateResult:
    onset_step: int | None
    events: list[SimEvent] = field(default_factory=list)
    fallback_step: int = 0

    @property
    def onset_event(self) -> SimEvent | None:
        return next((e for e in self.events if e.step == self.onset_step), None) if self.events else None


def idle_from(ev: Evidence) -> int:
    """First step after which nothing the robot does changes the evidence any more."""
    n = len(ev)
    signals = [ev.gripper_command.astype(np.float64)]
    for col in ("displacement", "eef_distance"):
        signals += [ev.col(col, o).astype(np.float64) for o in ev.objects]
    last_change = 0
    for sig in signals:
        moving = np.flatnonzero(np.abs(sig - sig[-1]) > IDLE_TOL_M)
        if len(moving):
            last_change = max(last_change, int(moving[-1]) + 1)
    return min(last_change, n - 1)


def localize(ev: Evidence, th: Thresholds | None = None) -> SimstateResult:
    events = detect_events(ev, th)
    rank = {k: i for i, k in enumerate(ONSET_PRIORITY)}
    events.sort(key=lambda e: (e.step, rank.get(e.kind, len(rank))))
    onset = events[0].step if events else None
    return SimstateResult(onset_step=onset, events=events, fallback_step=idle_from(ev))
