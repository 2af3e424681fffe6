"""Stage 1 as a `Stage` (pipeline/runner/stage.py): one unit per episode (task, init state).

Units: `units.plan_units(cfg)`; shards: `units.make_shards` (episodes of one task, one
environment per shard). Per episode the worker takes the task's environment, the policy
and its render process from its `WorkerContext`, runs and records the physics
(worker.run_physics) and hands the states to the render process, which draws the videos
while the next episodes run (the render-overlap stream, overlap.py); the episode is
finished (the runner writes `stage1/_done/<unit_id>.done` holding the EpisodeRecord) once
its videos are back, all before the shard returns, and on a fatal error too. An episode
that fails (an exception, a render process that died) is set aside: `stage1/errors/<unit_id>.txt` with the traceback,
no marker, so the next run redoes it from an emptied folder; its marker removes the file.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass
from pathlib import Path

from pipeline.atomic import write_text
from pipeline.config import Config, VideoConfig
from pipeline.layout import RunLayout
from pipeline.records import EpisodeRecord
from pipeline.runner import UnitResult, WorkerContext
from pipeline.stage1.overlap import Complete, RenderOverlapStage, Submit
from pipeline.stage1.units import EpisodeUnit, make_shards, plan_units
from pipeline.stage1.worker import PolicyFactory, run_one, run_physics, with_videos


@dataclass
class Stage1(RenderOverlapStage[EpisodeUnit]):
    cfg: Config
    policy_factory: PolicyFactory | None = None  # tests; default pipeline.policies.factory.make_policy
    name: str = "stage 1"

    @property
    def root(self) -> Path:
        return RunLayout.of(self.cfg).stage1.root

    def units(self, cfg: Config) -> list[EpisodeUnit]:
        return plan_units(cfg)

    def shards(self, units: list[EpisodeUnit], workers: int) -> list[tuple[EpisodeUnit, ...]]:
        return [s.units for s in make_shards(units, workers)]

    def shard_label(self, shard: tuple[EpisodeUnit, ...]) -> str:
        u = shard[0]
        return f"shard {u.suite}/{u.task} init states {','.join(str(x.init_state) for x in shard)}"

    def _env(self, unit: EpisodeUnit, ctx: WorkerContext):
        from pipeline.sim.registry import get_task

        return ctx.env(get_task(unit.suite, unit.task))

    def _policy(self, ctx: WorkerContext):
        cfg, factory = self.cfg.stage1.policy, self.policy_factory
        if factory is None:
            from pipeline.policies.factory import make_policy

            factory = make_policy
        # one policy per worker: a new config (or factory) replaces, and closes, the old one
        return ctx.policy(cfg.model_dump_json() + repr(self.policy_factory), lambda: factory(cfg), exclusive=True)

    def process(self, unit: EpisodeUnit, ctx: WorkerContext) -> UnitResult:
        """One episode with its videos rendered in this process (`stream` renders elsewhere)."""
        record = run_one(self._env(unit, ctx), self._policy(ctx), unit, self.cfg, self.root)
        return self._done(record)

    @staticmethod
    def _done(record: EpisodeRecord) -> UnitResult:
        return UnitResult(info=record.model_dump(mode="json"), ok=record.success)

    def _fail(self, unit: EpisodeUnit, reason: str, detail: str, text: str) -> UnitResult:
        write_text(RunLayout.of(self.cfg).stage1.error(unit.unit_id), text)
        return UnitResult.set_aside(reason, detail)

    def render_failed(self, unit: EpisodeUnit, error: str) -> UnitResult:
        return self._fail(unit, "RenderError", error.strip().splitlines()[-1], error)

    def set_aside(self, unit: EpisodeUnit, error: Exception) -> UnitResult:
        return self._fail(unit, type(error).__name__, str(error), traceback.format_exc())

    def worker_died(self, unit: EpisodeUnit, reason: str) -> None:
        write_text(RunLayout.of(self.cfg).stage1.error(unit.unit_id), f"worker died: {reason}\n")

    def after_done(self, unit: EpisodeUnit, result: UnitResult) -> None:
        RunLayout.of(self.cfg).stage1.error(unit.unit_id).unlink(missing_ok=True)

    @property
    def video(self) -> VideoConfig:
        return self.cfg.stage1.video

    def unit_env(self, unit: EpisodeUnit, ctx: WorkerContext):
        return self._env(unit, ctx)

    def simulate(self, unit: EpisodeUnit, ctx: WorkerContext, env, submit: Submit) -> Complete:
        """Physics here; a failed episode's states go to the render process (overlap.py)."""
        record, states = run_physics(env, self._policy(ctx), unit, self.cfg, self.root)
        if states is not None:
            submit(states, self.root / unit.rel_dir)
        return lambda videos: self._done(with_videos(record, videos[0], self.video.fps) if videos else record)
