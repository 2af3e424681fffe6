"""Local executor: a pool of spawned worker processes (the default).

Workers are spawned (not forked: EGL/MuJoCo state must not be shared), die with the
parent (PR_SET_PDEATHSIG), and send events through a multiprocessing queue handed over at
process start. Module globals of the work function (e.g. a cached environment) persist
across the items one worker process runs.
"""

from __future__ import annotations

import multiprocessing as mp
import queue as queue_mod
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from pipeline.executors.base import Executor, WorkFn, apply_worker_env, die_with_parent

_EVENTS = None  # the worker's end of the event queue


def _init_worker(events, env: dict[str, str] | None) -> None:
    global _EVENTS
    die_with_parent()
    apply_worker_env(env)
    _EVENTS = events


def _emit(event: Any) -> None:
    _EVENTS.put(event)


def _call(fn: WorkFn, item: Any) -> Any:
    return fn(item, _emit)


class LocalExecutor(Executor):
    def __init__(self, workers: int = 2, worker_env: dict[str, str] | None = None):
        if workers < 1:
            raise ValueError("workers must be >= 1")
        self.workers = workers
        self.worker_env = worker_env

    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None) -> list:
        if not items:
            return []
        ctx = mp.get_context("spawn")
        events = ctx.Queue()

        def drain() -> None:
            while True:
                try:
                    ev = events.get_nowait()
                except queue_mod.Empty:
                    return
                if on_event is not None:
                    on_event(ev)

        pool = ProcessPoolExecutor(
            max_workers=min(self.workers, len(items)),
            mp_context=ctx,
            initializer=_init_worker,
            initargs=(events, self.worker_env),
        )
        try:
            futures = [pool.submit(_call, fn, item) for item in items]
            pending = set(futures)
            while pending:
                done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                drain()
                for f in done:
                    f.result()  # re-raise a worker's exception now
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            for p in list((getattr(pool, "_processes", None) or {}).values()):
                p.kill()
            raise
        pool.shutdown(wait=True)  # workers exit and flush their queue feeders
        drain()
        return [f.result() for f in futures]


class InlineExecutor(Executor):
    """Runs everything in the calling process (debugging, profiling)."""

    workers = 1

    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None) -> list:
        emit = on_event or (lambda ev: None)
        return [fn(item, emit) for item in items]
