"""The one progress event every stage and executor emits.

A worker emits `started` before a unit, then `done` (its marker is written) or `set_aside`
(it failed with a reason; no marker, so a rerun tries it again). The executor emits `retry`
when a worker died under a shard and the shard runs again, and `set_aside` for each
unfinished unit of a shard whose workers kept dying. Events are small and picklable: they
cross process (local executor) and node (Ray) boundaries unchanged.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel

EventKind = Literal["started", "done", "set_aside", "retry"]


class Event(BaseModel):
    kind: EventKind
    unit: str  # the unit id (for `retry`: the label of the shard that runs again)
    stage: str = ""
    ok: bool | None = None  # the unit's own verdict where it has one (episode success, trial recovered)
    status: str | None = None  # a stage's name for the outcome (stage 2: scene / quarantine)
    reason: str | None = None  # why a unit was set aside or an attempt lost
    detail: str | None = None
    attempt: int | None = None  # retry: the attempt that was lost (1 = the first)
