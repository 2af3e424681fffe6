"""What went wrong in a skill, typed: a `Note` (kind + object) instead of "kind:object" strings.

`Ctx.events` collects notes in order; `ScriptedPolicy.events` hands them out as the same
"kind:object" strings as before (benchmarks, reports). `Outcome` is the truth record's
judgement of an attempt (`truth.py`); the note kinds it shares are the same members.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class Outcome(StrEnum):
    """How a skill attempt ended, as the truth record judges it (truth.parquet's `outcome`)."""

    ACHIEVED = "achieved"
    MISSED_GRASP = "missed_grasp"
    LOST_GRASP = "lost_grasp"
    DROPPED = "dropped"
    MISPLACED = "misplaced"
    KNOCKED = "knocked"
    HALF_OPEN = "half_open"
    NOT_TURNED = "not_turned"
    TIMEOUT = "timeout"


class Halt(StrEnum):
    """Notes that are no attempt's outcome: a skill or the expert stopped."""

    NO_STAGING_SPOT = "no_staging_spot"  # no table spot to turn a handle to the hand (insert.py)
    GIVE_UP = "give_up"  # the recovery expert gave up (the subject is its reason)


@dataclass(frozen=True)
class Note:
    kind: Outcome | Halt
    subject: str  # the object (or, for GIVE_UP, the reason)

    def __str__(self) -> str:
        return f"{self.kind}:{self.subject}"
