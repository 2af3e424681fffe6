"""Where work runs is configuration: a local process pool (default) or Ray.

The runner (pipeline/runner/) hands an executor a function and a list of picklable work
items; the function gets `(item, ctx)`, ctx being the worker's `WorkerContext`, and may
`ctx.emit(event)` small picklable events (progress) that reach the caller's `on_event` in
the main process. `inline` runs everything in the calling process. A worker that dies under an item costs that item
one attempt, never the run (see base.py). Only `ray.py` imports ray, inside its methods.
"""

from __future__ import annotations

from pipeline.config import ExecutorConfig
from pipeline.executors.base import Executor, RunReport, SetAside


def make_executor(cfg: ExecutorConfig, worker_env: dict[str, str] | None = None) -> Executor:
    """The configured executor; it carries `cfg.retry` for the runner (RetryableError policy)."""
    if cfg.kind == "ray":
        from pipeline.executors.ray import RayExecutor

        ex: Executor = RayExecutor(cfg.workers, cfg.ray_address, worker_env=worker_env, max_retries=cfg.max_retries)
    else:
        from pipeline.executors.local import InlineExecutor, LocalExecutor

        ex = InlineExecutor() if cfg.kind == "inline" else \
            LocalExecutor(cfg.workers, worker_env=worker_env, max_retries=cfg.max_retries)
    ex.retry = cfg.retry
    return ex


__all__ = ["Executor", "RunReport", "SetAside", "make_executor"]
