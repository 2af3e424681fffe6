"""Local executor: a pool of spawned worker processes (the default).

Workers are spawned (not forked: EGL/MuJoCo state must not be shared), die with the
parent (PR_SET_PDEATHSIG), and each talks to the caller over its own pipe: the caller sends
one item at a time, the worker sends back its events, then the item's result. Each worker
builds one `WorkerContext` and keeps it (its cached environment and policies) across the
items it runs; it closes it on a normal stop.

One pipe per worker is why this is not a `concurrent.futures.ProcessPoolExecutor`: that
pool, when any worker dies, fails every item in flight with BrokenProcessPool and kills
the other workers. Here the caller knows which item each worker holds, so a dead worker
(kill -9, OOM killer, segfault) costs only its own item one attempt; the item is retried
on a fresh worker, up to `max_retries` times, then set aside (see base.py). The other
workers keep running, and keep their environments.
"""

from __future__ import annotations

import multiprocessing as mp
import pickle
import signal
import threading
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from pipeline.executors.base import (Executor, RunReport, WorkFn, apply_worker_env, default_label, die_with_parent,
                                     retry_or_set_aside)
from pipeline.runner.context import WorkerContext

_STOP = b""  # the caller's "no more items" message


class _RemoteTraceback(Exception):
    """Carries a worker's formatted traceback as the `__cause__` of the re-raised error."""

    def __str__(self) -> str:
        return self.args[0]


def _portable(exc: BaseException) -> bytes:
    """Pickle an exception, or a RuntimeError naming it when it does not pickle round-trip."""
    try:
        data = pickle.dumps(exc)
        pickle.loads(data)  # exception classes with required init args pickle but do not load
        return data
    except Exception:
        return pickle.dumps(RuntimeError(f"{type(exc).__name__}: {exc}"))


def _worker_main(conn: Connection, env: dict[str, str] | None) -> None:
    die_with_parent()
    apply_worker_env(env)
    lock = threading.Lock()  # a work function may emit from its own threads

    def emit(event: Any) -> None:
        with lock:
            conn.send(("event", event))

    ctx = WorkerContext(emit)
    while True:
        try:
            msg = conn.recv_bytes()
        except EOFError:  # the caller is gone
            return
        if msg == _STOP:
            ctx.close()
            return  # a normal exit: atexit handlers (renderer teardown) run
        try:
            fn, item = pickle.loads(msg)
            result = fn(item, ctx)
            reply = pickle.dumps(("done", result))
        except BaseException as e:  # everything the caller must re-raise, pickling errors included
            reply = pickle.dumps(("error", _portable(e), traceback.format_exc()))
        with lock:
            conn.send_bytes(reply)


@dataclass
class _Worker:
    proc: Any  # multiprocessing.Process (spawn context)
    conn: Connection
    item: int | None = None  # index of the item it holds


def _death(proc) -> str:
    code = proc.exitcode
    if code is not None and code < 0:
        try:
            return f"worker pid {proc.pid} killed by {signal.Signals(-code).name}"
        except ValueError:
            pass
    return f"worker pid {proc.pid} exited with code {code} while running it"


class LocalExecutor(Executor):
    def __init__(self, workers: int = 2, worker_env: dict[str, str] | None = None, max_retries: int = 2):
        if workers < 1:
            raise ValueError("workers must be >= 1")
        if max_retries < 0:
            raise ValueError("max_retries must be >= 0")
        self.workers = workers
        self.worker_env = worker_env
        self.max_retries = max_retries
        self.report = RunReport()

    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None,
            label: Callable[[int, Any], str] = default_label) -> list:
        self.report = report = RunReport()
        if not items:
            return []
        ctx = mp.get_context("spawn")
        size = min(self.workers, len(items))
        todo: deque[int] = deque(range(len(items)))
        attempts = [0] * len(items)
        results: list[Any] = [None] * len(items)
        left = len(items)
        pool: list[_Worker] = []

        def spawn() -> _Worker:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker_main, args=(child, self.worker_env))
            proc.start()
            child.close()  # so the caller's end sees EOF when the worker dies
            w = _Worker(proc, parent)
            pool.append(w)
            return w

        def assign(w: _Worker) -> None:
            i = todo.popleft()
            w.item = i
            attempts[i] += 1
            try:
                w.conn.send_bytes(pickle.dumps((fn, items[i])))
            except (BrokenPipeError, ConnectionResetError):
                pass  # died idle; the next wait() sees it and the item is counted as lost there

        def handle(w: _Worker, msg: tuple) -> None:
            nonlocal left
            if msg[0] == "event":
                if on_event is not None:
                    on_event(msg[1])
                return
            i, w.item = w.item, None
            if msg[0] == "error":
                try:
                    exc = pickle.loads(msg[1])
                except Exception:  # its class exists only where the worker imported it
                    exc = RuntimeError(msg[2].strip().splitlines()[-1])
                exc.__cause__ = _RemoteTraceback(msg[2])
                raise exc
            results[i] = msg[1]
            left -= 1

        def buried(w: _Worker) -> None:
            """A dead worker: retry or set aside its item; the pool refills on the next turn."""
            nonlocal left
            w.proc.join(5)
            if w.proc.is_alive():  # its pipe broke but it lingers: it must not go on writing
                w.proc.kill()
                w.proc.join()
            w.conn.close()
            pool.remove(w)
            i = w.item
            if i is None:
                return
            reason = _death(w.proc)
            aside = retry_or_set_aside(report, i, label(i, items[i]), attempts[i], reason, self.max_retries, on_event)
            if aside is None:
                todo.appendleft(i)  # first in line: a poison item is settled early
            else:
                results[i] = aside
                left -= 1

        clean = False
        try:
            while left:
                for w in pool:
                    if w.item is None and todo:
                        assign(w)
                while todo and len(pool) < size:
                    assign(spawn())
                ready = set(wait([w.conn for w in pool] + [w.proc.sentinel for w in pool]))
                for w in list(pool):
                    if w.conn not in ready and w.proc.sentinel not in ready:
                        continue
                    try:
                        # read everything it sent before looking at its death: a result that
                        # arrived just before the worker died still counts
                        while w.conn.poll():
                            handle(w, w.conn.recv())
                        dead = not w.proc.is_alive()
                    except (EOFError, ConnectionResetError):
                        dead = True
                    if dead:
                        buried(w)
            clean = True
        finally:
            for w in pool:
                if clean:
                    try:
                        w.conn.send_bytes(_STOP)
                    except OSError:
                        pass
                else:
                    w.proc.kill()
            for w in pool:
                w.proc.join(60)  # a clean exit tears down renderers; a stuck one is killed
                if w.proc.is_alive():
                    w.proc.kill()
                    w.proc.join()
                w.conn.close()
        report.log()
        return results


class InlineExecutor(Executor):
    """Runs everything in the calling process (`executor.kind: inline`: debugging, profiling,
    tests that patch something in this process). One WorkerContext per run, closed after it."""

    workers = 1

    def __init__(self, workers: int = 1, worker_env: dict[str, str] | None = None, max_retries: int = 0):
        self.report = RunReport()

    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None,
            label: Callable[[int, Any], str] = default_label) -> list:
        self.report = RunReport()
        ctx = WorkerContext(on_event)
        try:
            return [fn(item, ctx) for item in items]
        finally:
            ctx.close()
