"""The stage contract: a stage declares its units and processes one; the runner does the rest.

A `Stage` says which units a run has (`units(cfg)`), how to process one in a worker
(`process(unit, ctx)` -> `UnitResult`), where its done markers live (`root`) and, when a
unit's inputs can change after it is done, what they are (`fingerprint`). The runner
(runner.py) owns everything around that: skipping done units, writing the marker last,
retrying shards whose worker died and units that raised `RetryableError` (retry.py),
setting failed units aside, events and the progress bar.

Invariants a stage keeps: `process` writes its outputs atomically (pipeline/atomic.py), so a
unit run twice (a retry) leaves them once; a stage object pickles (it travels to workers);
per-unit caches live in the `WorkerContext`, never in module globals.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any, Generic, TypeVar

from pydantic import BaseModel

from pipeline.errors import FatalError, RetryableError
from pipeline.runner.context import WorkerContext
from pipeline.runner.retry import call_with_retries

U = TypeVar("U")


class UnitResult(BaseModel):
    """What processing one unit came to. `done`: write its marker, recording `info` (and the
    inputs' fingerprint); otherwise it is set aside with `reason` and a rerun tries again."""

    done: bool = True
    info: dict[str, Any] = {}
    ok: bool | None = None
    status: str | None = None
    reason: str | None = None
    detail: str | None = None
    inputs: Any = None  # fingerprint (str or dict) taken before the unit's inputs were read

    @classmethod
    def set_aside(cls, reason: str, detail: str = "") -> UnitResult:
        return cls(done=False, reason=reason, detail=detail)


class Stage(ABC, Generic[U]):
    name: str

    @property
    @abstractmethod
    def root(self) -> Path:
        """The folder whose `_done/` holds this stage's markers."""

    @abstractmethod
    def units(self, cfg) -> list[U]:
        """Every unit of the run, done or not, in a stable order."""

    @abstractmethod
    def process(self, unit: U, ctx: WorkerContext) -> UnitResult:
        """Process one unit in a worker; write its outputs (not its marker)."""

    def unit_id(self, unit: U) -> str:
        return unit.unit_id  # type: ignore[attr-defined]

    def marker_id(self, unit: U) -> str:
        """Name of the unit's done marker (a stage may add e.g. the model that made it)."""
        return self.unit_id(unit)

    def fingerprint(self, unit: U) -> Any:
        """What the unit's outputs are computed from (recorded in its marker as `inputs`);
        a done unit whose fingerprint changed runs again. None: inputs never change."""
        return None

    def forget(self, unit: U) -> None:
        """Drop what a done unit's old inputs produced that a redo would not overwrite."""

    def set_aside(self, unit: U, error: Exception) -> UnitResult | None:
        """Record why `unit` failed (the stage's own set-aside file) and return the result;
        None re-raises the error (it stops the run)."""
        return None

    def worker_died(self, unit: U, reason: str) -> None:
        """A unit left unfinished because its shard's workers kept dying."""

    def after_done(self, unit: U, result: UnitResult) -> None:
        """After the marker: clear what an earlier failed attempt left (e.g. its error file)."""

    def group(self, unit: U) -> Hashable:
        """Units of one group share a shard (one environment build per shard)."""
        return self.unit_id(unit)

    def shards(self, units: list[U], workers: int) -> list[tuple[U, ...]]:
        """Group units by `group`; split a group only when there are too few groups to keep
        every worker busy (each split costs one more environment build)."""
        groups: dict[Hashable, list[U]] = {}
        for u in units:
            groups.setdefault(self.group(u), []).append(u)
        per_group = max(1, math.ceil(workers / max(1, len(groups))))
        out = []
        for g in groups.values():
            n = min(per_group, len(g))
            size = math.ceil(len(g) / n)
            out += [tuple(g[i:i + size]) for i in range(0, len(g), size)]
        return out

    def shard_label(self, shard: tuple[U, ...]) -> str:
        ids = [self.unit_id(u) for u in shard]
        return ids[0] if len(ids) == 1 else f"{ids[0]} (+{len(ids) - 1})"

    def stream(self, units: list[U], ctx: WorkerContext, finish: Callable[[U, UnitResult], None]) -> None:
        """Process a shard's units, calling `finish(unit, result)` as each completes (the
        runner writes its marker then). A stage that finishes units out of order (stage 1's
        videos) overrides this; it must still finish what completed before a FatalError."""
        for unit in units:
            ctx.emit(self.event("started", unit))
            finish(unit, self.run_unit(unit, ctx))

    def run_unit(self, unit: U, ctx: WorkerContext) -> UnitResult:
        """`process(unit)`, tried again on RetryableError (`ctx.retry`, each lost try a `retry`
        event); any other failure but a FatalError becomes the stage's set-aside, and so does
        a RetryableError after the last try."""
        inputs = self.fingerprint(unit)  # before reading: a file changed meanwhile is redone
        try:
            result = call_with_retries(lambda: self.process(unit, ctx), ctx.retry,
                                       lambda k, e, wait: ctx.emit(self.retry_event(unit, k, e, wait)))
        except FatalError:
            raise
        except Exception as e:  # one unit's failure must not cost the shard's others
            result = self.set_aside(unit, e)
            if result is None:
                if not isinstance(e, RetryableError):
                    raise
                result = UnitResult.set_aside(type(e).__name__, f"{e} (gave up after {ctx.retry.tries} tries)")
        return result.model_copy(update={"inputs": inputs})

    def retry_event(self, unit: U, lost: int, error: Exception, wait_s: float):
        from pipeline.runner.events import Event

        return Event(kind="retry", unit=self.unit_id(unit), stage=self.name, attempt=lost,
                     reason=f"{type(error).__name__}: {error}"[:300], detail=f"next try in {wait_s:.1f} s")

    def event(self, kind: str, unit: U, result: UnitResult | None = None):
        from pipeline.runner.events import Event

        r = result or UnitResult()
        return Event(kind=kind, unit=self.unit_id(unit), stage=self.name, ok=r.ok if result else None,
                     status=r.status if result else None, reason=r.reason if result else None,
                     detail=r.detail if result else None)
