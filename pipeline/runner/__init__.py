"""One contract for every stage: a `Stage` declares and processes units; the `Runner` owns
done markers, resumption, set-aside, retries, events and progress; each worker keeps a
`WorkerContext` (environment, policies, helpers) across its units. See stage.py."""

from pipeline.runner.context import WorkerContext
from pipeline.runner.events import Event
from pipeline.runner.stage import Stage, UnitResult

__all__ = ["Event", "Runner", "RunStats", "Stage", "UnitResult", "WorkerContext"]


def __getattr__(name):  # the runner imports the executors; keep `import pipeline.runner` light
    if name in ("Runner", "RunStats"):
        from pipeline.runner import runner

        return getattr(runner, name)
    raise AttributeError(name)
