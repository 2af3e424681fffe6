"""The evaluation as a `Stage`: one unit per trial (pipeline/runner/stage.py).

Inputs: the run's `Config` and the scenes found by `run.run`. Per trial the worker takes
the scene's environment and the policy (by name and chunk size) from its `WorkerContext`,
runs the trial and writes `trials/<unit>.parquet`; the runner then writes
`_done/<unit>.done` (`{"success", "steps"}`). A trial that cannot run (EpisodeError) is set
aside: `quarantine/<unit>.json` with the reason, no marker; a later success removes it.
Any other error stops the run. Trials of one task share a shard (one environment build).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.errors import EpisodeError
from pipeline.eval.plan import plan_trials, policy_name
from pipeline.eval.protocol import Trial
from pipeline.eval.records import write_episodes
from pipeline.eval.scenes import Scene
from pipeline.layout import EvalLayout
from pipeline.runner import Stage, UnitResult, WorkerContext


@dataclass
class EvalStage(Stage[Trial]):
    cfg: Config
    out_dir: str
    scenes: list[Scene]
    name: str = "eval"

    @property
    def root(self) -> Path:
        return Path(self.out_dir)

    def units(self, cfg: Config) -> list[Trial]:
        trials, self.problems = plan_trials(cfg, self.scenes)
        return trials

    def group(self, trial: Trial):
        return trial.scene.suite, trial.scene.task

    def _policy(self, trial: Trial, ctx: WorkerContext):
        """The worker's instance of a policy at a chunk size (built once per worker)."""

        def build():
            from pipeline.policies.factory import make_policy

            cfg = next(p for p in self.cfg.eval.policies if policy_name(p) == trial.policy)
            if cfg.kind == "scripted":  # let the expert plan chunks as long as the runner executes
                cfg = cfg.model_copy(update={"scripted": cfg.scripted.model_copy(
                    update={"chunk_len": trial.chunk_size})})
            return make_policy(cfg)

        return ctx.policy(f"{trial.policy}@{trial.chunk_size}", build)

    def process(self, trial: Trial, ctx: WorkerContext) -> UnitResult:
        from pipeline.eval.protocol import run_trial
        from pipeline.eval.scenes import scene_task

        env = ctx.env(scene_task(trial.scene))
        ep = run_trial(env, self._policy(trial, ctx), trial)
        write_episodes(EvalLayout(self.root).trial(trial.unit_id), [ep])
        return UnitResult(info={"success": ep.success, "steps": ep.steps}, ok=ep.success)

    def set_aside(self, trial: Trial, error: Exception) -> UnitResult | None:
        if not isinstance(error, EpisodeError):
            return None  # not a per-trial outcome: stop the run
        uid = trial.unit_id
        write_json(EvalLayout(self.root).quarantine(uid), {"unit_id": uid, "scene_id": trial.scene.scene_id,
                                                           "reason": error.reason, "detail": error.detail})
        return UnitResult.set_aside(error.reason, error.detail)

    def after_done(self, trial: Trial, result: UnitResult) -> None:
        EvalLayout(self.root).quarantine(trial.unit_id).unlink(missing_ok=True)  # an earlier failed attempt
