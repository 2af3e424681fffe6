"""Why the recovery expert stopped short of the goal (set on the policy as `give_up_reason`)."""

from __future__ import annotations

from enum import StrEnum


class GiveUpReason(StrEnum):
    UNREACHABLE = "unreachable"  # a goal object or part lies outside the arm's workspace
    OBJECT_OFF_TABLE = "object_off_table"  # a goal object fell below the table top
    TIMEOUT = "timeout"  # the step budget ran out (or the episode ended) before the goal
    NO_PLAN = "no_plan"  # no skill applies: nothing left to try in this state
    RETRIES_EXHAUSTED = "retries_exhausted"  # every variant of a subgoal was tried and failed


class GiveUp(Exception):
    """Raised inside the planner; the expert records the reason and holds still."""

    def __init__(self, reason: GiveUpReason, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else str(reason))
        self.reason = reason
        self.detail = detail
