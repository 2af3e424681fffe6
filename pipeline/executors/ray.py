"""Ray executor: the same contract on a Ray cluster (`executor.kind: ray`).

`ray_address` comes from the config (None starts or joins a local Ray). Events travel
through a `ray.util.queue.Queue`. This is the only module that imports ray, and only inside
methods, so the rest of the project runs without it installed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.errors import FatalError
from pipeline.executors.base import Executor, WorkFn


def _ray_call(fn: WorkFn, item: Any, events, env: dict[str, str] | None) -> Any:
    from pipeline.executors.base import apply_worker_env

    apply_worker_env(env)
    return fn(item, lambda ev: events.put(ev))


class RayExecutor(Executor):
    def __init__(self, workers: int = 2, address: str | None = None, worker_env: dict[str, str] | None = None):
        self.workers = workers
        self.address = address
        self.worker_env = worker_env

    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None) -> list:
        try:
            import ray
            from ray.util.queue import Empty, Queue
        except ImportError:
            raise FatalError("executor.kind is ray but ray is not installed (pip install 'libero-recover[ray]')") from None
        if not items:
            return []
        started = not ray.is_initialized()
        if started:
            kwargs = {"address": self.address} if self.address else {"num_cpus": self.workers}
            # runtime_env sets the variables before the worker process starts (Mesa reads them once)
            ray.init(**kwargs, runtime_env={"env_vars": self.worker_env or {}}, log_to_driver=False)
        try:
            events = Queue()
            remote = ray.remote(num_cpus=1, max_retries=0)(_ray_call)
            refs = [remote.remote(fn, item, events, self.worker_env) for item in items]

            def drain() -> None:
                while True:
                    try:
                        batch = events.get_nowait_batch(max(1, events.qsize()))
                    except Empty:
                        return
                    if not batch:
                        return
                    for ev in batch:
                        if on_event is not None:
                            on_event(ev)

            pending = list(refs)
            while pending:
                done, pending = ray.wait(pending, num_returns=1, timeout=0.2)
                drain()
                for r in done:
                    ray.get(r)  # re-raise a task's exception now
            drain()
            results = ray.get(refs)
            events.shutdown()
            return results
        finally:
            if started:
                ray.shutdown()
