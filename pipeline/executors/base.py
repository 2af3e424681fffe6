"""The executor contract: run `fn(item, emit)` for every item, somewhere, and relay events.

Inputs: a top-level (picklable) function, picklable items, an `on_event` callback.
Outputs: the functions' return values, in item order.
Invariants: `on_event` runs in the calling process only; an exception raised by `fn`
stops the run and is re-raised by `run` (per-item errors that should not stop a run are
the function's business: catch them and emit/return them); workers never outlive the
caller (a killed caller leaves no worker behind writing files).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

Emit = Callable[[Any], None]
WorkFn = Callable[[Any, Emit], Any]


class Executor(ABC):
    workers: int

    @abstractmethod
    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None) -> list:
        """Run `fn(item, emit)` for each item; return results in item order."""


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
