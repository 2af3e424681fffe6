"""Ray executor: the same contract on a Ray cluster (`executor.kind: ray`).

`ray_address` comes from the config (None starts a fresh local Ray instance; give the
address to join a running cluster). Work runs on a pool of `workers` actors, one CPU each;
each actor holds one `WorkerContext` (its environment and policies) across the items it
runs, like a local worker process, and closes it when the run ends. Events travel through a
`ray.util.queue.Queue`, an actor pinned to the driver's node so that losing a worker node
never loses it. This is the only module that imports ray, and only inside methods, so the
rest of the project runs without it installed.

Items whose actor dies under them (its process killed, its node lost, a lost result, the
memory monitor's kill) are resubmitted by this loop to a live actor, and a replacement
actor is started; so the run's report names every lost attempt, and after `max_retries`
more attempts the item is set aside (base.py). A result is fetched as soon as its item
ends, so a node lost later does not take finished results with it. An exception raised by
the work function itself (RayTaskError) still stops the run.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from pipeline.errors import FatalError
from pipeline.executors.base import Executor, RunReport, WorkFn, default_label, retry_or_set_aside


class _Worker:
    """One Ray actor (wrapped by `ray.remote` in `run`): a worker and its WorkerContext."""

    def __init__(self, env: dict[str, str] | None, events):
        from pipeline.executors.base import apply_worker_env
        from pipeline.runner.context import WorkerContext

        apply_worker_env(env)
        self.ctx = WorkerContext(lambda ev: events.put(ev))

    def ready(self) -> bool:
        return True

    def run(self, fn: WorkFn, item: Any) -> Any:
        return fn(item, self.ctx)

    def close(self) -> None:
        self.ctx.close()


def _lost_worker_errors(ray) -> tuple[type, ...]:
    """Failures of the machinery under an item, not of the work function: worth retrying."""
    ex = ray.exceptions
    return ex.RayActorError, ex.WorkerCrashedError, ex.NodeDiedError, ex.ObjectLostError, ex.OutOfMemoryError


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
        running: dict[Any, tuple[int, Any]] = {}  # item ref -> (item index, actor)
        starting: dict[Any, Any] = {}  # ready ref -> actor not yet known to be up
        idle: deque = deque()
        try:
            here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
            events = Queue(actor_options={"num_cpus": 0, "scheduling_strategy": here})
            # max_restarts=0: this loop replaces a dead actor and resubmits, so each lost attempt is counted
            actor_cls = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(_Worker)
            todo: deque[int] = deque(range(len(items)))
            attempts = [0] * len(items)
            results: list[Any] = [None] * len(items)

            def start() -> None:
                actor = actor_cls.remote(self.worker_env, events)
                starting[actor.ready.remote()] = actor

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

            def lost(i: int, e: Exception) -> None:
                reason = f"{type(e).__name__}: {(str(e).strip().splitlines() or [''])[0][:200]}"
                aside = retry_or_set_aside(report, i, label(i, items[i]), attempts[i], reason, self.max_retries,
                                           on_event)
                if aside is None:
                    todo.appendleft(i)  # first in line: a poison item is settled early
                else:
                    results[i] = aside

            for _ in range(min(self.workers, len(items))):
                start()
            while todo or running:
                while todo and idle:
                    actor, i = idle.popleft(), todo.popleft()
                    attempts[i] += 1
                    running[actor.run.remote(fn, items[i])] = (i, actor)
                done, _ = ray.wait(list(running) + list(starting), num_returns=1, timeout=0.2)
                drain()
                for ref in done:
                    if ref in starting:
                        actor = starting.pop(ref)
                        try:
                            ray.get(ref)
                            idle.append(actor)
                        except lost_worker:
                            start()  # it died starting up (its node went away): try another
                        continue
                    i, actor = running.pop(ref)
                    try:
                        results[i] = ray.get(ref)  # re-raises the work function's own exception now
                        idle.append(actor)
                    except lost_worker as e:
                        ray.kill(actor, no_restart=True)
                        start()
                        lost(i, e)
            drain()
            for actor in idle:  # a clean end: release environments and policies
                try:
                    ray.get(actor.close.remote(), timeout=60)
                except Exception:  # noqa: BLE001 - closing is best effort; the actor is killed next
                    pass
            events.shutdown()
        finally:
            # killing the actors stops what they run: a stopped run leaves nothing behind writing files
            for actor in [a for _, a in running.values()] + list(starting.values()) + list(idle):
                try:
                    ray.kill(actor, no_restart=True)
                except Exception:  # noqa: BLE001 - already gone
                    pass
            if started:
                ray.shutdown()
        report.log()
        return results
