"""What one worker keeps across the units it runs: the `WorkerContext`.

The executor builds one per worker (a spawned local process, a Ray worker process, or the
caller for the inline executor) and hands it to every unit that worker runs, so the
current task's environment, the built policies and long-lived helpers (stage 1's render
process, stage 3's review-database engine and characterizer, a VLM client) are built once
per worker, not once per unit: a stage holds only the factories (`helper(name, build)`),
so the stage object stays picklable and each worker builds its own. `close()` releases
them (EGL contexts, sockets, child processes, database connections); the executor calls
it when the worker stops.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


class WorkerContext:
    def __init__(self, emit: Callable[[Any], None] | None = None):
        from pipeline.config import RetryConfig

        self.emit: Callable[[Any], None] = emit or (lambda ev: None)
        self.retry = RetryConfig()  # the current run's; `run_shard` sets it from the runner's job
        self._envs = None  # EnvCache, built on first use (imports the simulator)
        self._policies: dict[str, Any] = {}
        self._helpers: dict[str, Any] = {}
        self._closers: dict[str, Callable[[Any], None]] = {}

    def env(self, task):
        """The environment of `task` (a TaskSpec): the worker keeps the last task's one."""
        if self._envs is None:
            from pipeline.sim import EnvCache

            self._envs = EnvCache(capacity=1)
        return self._envs.get(task)

    @property
    def env_builds(self) -> int:
        return self._envs.builds if self._envs is not None else 0

    def policy(self, key: str, build: Callable[[], Any], exclusive: bool = False):
        """The policy cached under `key`, built on first use. `exclusive`: keep only this one
        (a worker that switches policy config closes the old one first)."""
        if key not in self._policies:
            if exclusive:
                self._close_policies()
            self._policies[key] = build()
        return self._policies[key]

    def helper(self, name: str, build: Callable[[], Any], alive: Callable[[Any], bool] = lambda h: True,
               close: Callable[[Any], None] | None = None):
        """A long-lived helper object built by `build()` on first use, rebuilt when `alive`
        says it died; `close(h)` releases it (default `h.close()`; an engine's is `dispose`)."""
        h = self._helpers.get(name)
        if h is None or not alive(h):
            if h is not None:
                self._close(name, h)
            h = self._helpers[name] = build()
            if close is not None:
                self._closers[name] = close
        return h

    def _close(self, name: str, h: Any) -> None:
        closer = self._closers.pop(name, None)
        closer(h) if closer is not None else h.close()

    def peek(self, name: str):
        """The helper `name` if built, else None (never builds one)."""
        return self._helpers.get(name)

    def _close_policies(self) -> None:
        while self._policies:
            _, p = self._policies.popitem()
            p.close()

    def close(self) -> None:
        while self._helpers:
            self._close(*self._helpers.popitem())
        self._close_policies()
        if self._envs is not None:
            self._envs.close()
            self._envs = None

    @property
    def empty(self) -> bool:
        return self._envs is None and not self._policies and not self._helpers
