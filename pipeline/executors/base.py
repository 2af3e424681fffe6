"""The executor contract: run `fn(item, ctx)` for every item, somewhere, and relay events.

Inputs: a top-level (picklable) function, picklable items, an `on_event` callback. `ctx` is
the worker's `WorkerContext` (pipeline/runner/context.py): built once per worker, kept
across the items it runs (its environment and policy caches), closed when it stops;
`ctx.emit(event)` relays an event to `on_event`. When a worker dies under an item and the
item runs again, the executor itself emits a `retry` Event (pipeline/runner/events.py).
Outputs: the functions' return values, in item order; `executor.report` says what was retried.
Invariants: `on_event` runs in the calling process only; an exception raised by `fn`
stops the run and is re-raised by `run` (per-item errors that should not stop a run are
the function's business: catch them and emit/return them); workers never outlive the
caller (a killed caller leaves no worker behind writing files).

Faults are not exceptions: a worker that dies under an item (kill -9, OOM killer, segfault,
a lost Ray node) costs only that item an attempt. It is run again, up to `max_retries` more
times; after that its result slot holds a `SetAside` record with the reason and the run
goes on. Every other item completes. So `fn` may run more than once for an item, and must
write its outputs atomically (pipeline/atomic.py) so a retry never duplicates them.
"""

from __future__ import annotations

import logging
import os
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

from pydantic import BaseModel

log = logging.getLogger("pipeline.executors")

Emit = Callable[[Any], None]
WorkFn = Callable[[Any, Any], Any]  # (item, WorkerContext) -> result


class Retry(BaseModel):
    """One attempt of an item lost to a dead worker, and run again."""

    item: int  # index into the items list
    label: str
    attempt: int  # 1 = the first attempt was lost
    reason: str


class SetAside(BaseModel):
    """An item whose workers died on every allowed attempt; it stands in for its result."""

    item: int
    label: str
    attempts: int
    reason: str


class RunReport(BaseModel):
    retried: list[Retry] = []
    set_aside: list[SetAside] = []

    def summary(self) -> str:
        """One line per retry and per item set aside; empty when nothing went wrong."""
        lines = [f"retried {r.label} (attempt {r.attempt} lost: {r.reason})" for r in self.retried]
        lines += [f"set aside {s.label} after {s.attempts} attempt(s): {s.reason}" for s in self.set_aside]
        if not lines:
            return ""
        head = f"executor: {len(self.retried)} attempt(s) lost to dead workers and retried, " \
               f"{len(self.set_aside)} item(s) set aside"
        return "\n".join([head] + ["  " + line for line in lines])

    def log(self) -> None:
        # every caller gets the summary (stderr when logging is not configured); stage 1 also records it
        if text := self.summary():
            log.warning(text)


def default_label(index: int, _item: Any) -> str:
    return f"item {index}"


class Executor(ABC):
    workers: int
    max_retries: int = 2
    retry: Any = None  # the config's RetryConfig for the runner (make_executor sets it); never used here
    report: RunReport = RunReport()  # of the last run

    @abstractmethod
    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None,
            label: Callable[[int, Any], str] = default_label) -> list:
        """Run `fn(item, ctx)` for each item; return results in item order (a `SetAside` for
        an item whose workers kept dying); `label(index, item)` names items in the report."""


def retry_event(r: Retry):
    from pipeline.runner.events import Event

    return Event(kind="retry", unit=r.label, reason=r.reason, attempt=r.attempt)


def retry_or_set_aside(report: RunReport, item: int, label: str, attempt: int, reason: str, max_retries: int,
                       on_event: Callable[[Any], None] | None) -> SetAside | None:
    """An item whose worker died: None when it is to run again (a retry, reported), else the
    `SetAside` once its attempts are used up (one rule for every executor)."""
    if attempt <= max_retries:
        report.retried.append(Retry(item=item, label=label, attempt=attempt, reason=reason))
        if on_event is not None:
            on_event(retry_event(report.retried[-1]))
        return None
    aside = SetAside(item=item, label=label, attempts=attempt, reason=reason)
    report.set_aside.append(aside)
    return aside


def die_with_parent() -> None:
    """Ask Linux to SIGKILL this process when its parent dies (no orphaned workers)."""
    try:
        import ctypes
        import signal

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:  # not Linux: best effort
        pass


def apply_worker_env(env: dict[str, str] | None) -> None:
    """Set environment variables in a fresh worker before any library reads them."""
    for k, v in (env or {}).items():
        os.environ[k] = v
