"""Ray executor: the same contract on a Ray cluster (`executor.kind: ray`).

`ray_address` comes from the config (None starts a fresh local Ray instance; give the
address to join a running cluster). Events travel
through a `ray.util.queue.Queue`, an actor pinned to the driver's node so that losing a
worker node never loses it. This is the only module that imports ray, and only inside
methods, so the rest of the project runs without it installed.

Items whose task dies with its worker or node (WorkerCrashedError, NodeDiedError, a lost
result, the memory monitor's kill) are resubmitted by this loop rather than by Ray's own
`max_retries`, so the run's report names every lost attempt; after `max_retries` more
attempts the item is set aside (base.py). A result is fetched as soon as its task ends, so
a node lost later does not take finished results with it. An exception raised by the work
function itself (RayTaskError) still stops the run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pipeline.errors import FatalError
from pipeline.executors.base import Executor, Retry, RunReport, SetAside, WorkFn, default_label, retry_event

# The WorkerContext of this Ray worker process: Ray reuses a worker process for the tasks of
# one job, so like a local worker it keeps its environment and policies across items.
_CONTEXT = None


def _ray_call(fn: WorkFn, item: Any, events, env: dict[str, str] | None) -> Any:
    global _CONTEXT
    from pipeline.executors.base import apply_worker_env
    from pipeline.runner.context import WorkerContext

    apply_worker_env(env)
    if _CONTEXT is None:
        _CONTEXT = WorkerContext()
    _CONTEXT.emit = lambda ev: events.put(ev)  # this run's queue
    return fn(item, _CONTEXT)


def _lost_worker_errors(ray) -> tuple[type, ...]:
    """Failures of the machinery under a task, not of the work function: worth retrying."""
    ex = ray.exceptions
    return ex.WorkerCrashedError, ex.NodeDiedError, ex.ObjectLostError, ex.OutOfMemoryError


class RayExecutor(Executor):
    def __init__(self, workers: int = 2, address: str | None = None, worker_env: dict[str, str] | None = None,
                 max_retries: int = 2):
        if max_retries < 0:
            raise ValueError("max_retries must be >= 0")
        self.workers = workers
        self.address = address
        self.worker_env = worker_env
        self.max_retries = max_retries
        self.report = RunReport()

    def run(self, fn: WorkFn, items: list, on_event: Callable[[Any], None] | None = None,
            label: Callable[[int, Any], str] = default_label) -> list:
        try:
            import ray
            from ray.util.queue import Empty, Queue
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy
        except ImportError:
            raise FatalError("executor.kind is ray but ray is not installed (pip install 'libero-recover[ray]')") from None
        self.report = report = RunReport()
        if not items:
            return []
        started = not ray.is_initialized()
        if started:
            # "local": a fresh instance, never one found by address file (a cluster still shutting
            # down from the previous run, which would refuse num_cpus)
            kwargs = {"address": self.address} if self.address else {"address": "local", "num_cpus": self.workers}
            # runtime_env sets the variables before the worker process starts (Mesa reads them once)
            ray.init(**kwargs, runtime_env={"env_vars": self.worker_env or {}}, log_to_driver=False)
        lost_worker = _lost_worker_errors(ray)
        pending: dict[Any, int] = {}  # task ref -> item index
        try:
            here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
            events = Queue(actor_options={"num_cpus": 0, "scheduling_strategy": here})
            # max_retries=0: this loop resubmits, so each lost attempt is seen and counted
            remote = ray.remote(num_cpus=1, max_retries=0)(_ray_call)
            attempts = [0] * len(items)
            results: list[Any] = [None] * len(items)

            def submit(i: int) -> None:
                attempts[i] += 1
                pending[remote.remote(fn, items[i], events, self.worker_env)] = i

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

            for i in range(len(items)):
                submit(i)
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1, timeout=0.2)
                drain()
                for ref in done:
                    i = pending.pop(ref)
                    try:
                        results[i] = ray.get(ref)  # re-raises a task's own exception now
                    except lost_worker as e:
                        reason = f"{type(e).__name__}: {(str(e).strip().splitlines() or [''])[0][:200]}"
                        if attempts[i] <= self.max_retries:
                            report.retried.append(Retry(item=i, label=label(i, items[i]), attempt=attempts[i],
                                                        reason=reason))
                            if on_event is not None:
                                on_event(retry_event(report.retried[-1]))
                            submit(i)
                        else:
                            results[i] = SetAside(item=i, label=label(i, items[i]), attempts=attempts[i],
                                                  reason=reason)
                            report.set_aside.append(results[i])
            drain()
            events.shutdown()
        except BaseException:
            for ref in pending:  # a stopped run leaves no task behind writing files
                ray.cancel(ref, force=True)
            raise
        finally:
            if started:
                ray.shutdown()
        report.log()
        return results
