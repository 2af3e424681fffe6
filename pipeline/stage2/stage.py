"""Stage 2 as a `Stage` (pipeline/runner/stage.py): one unit per failed episode.

Units: the failed EpisodeRecords of the stage-1 manifest (`pending.read_failures`, which
also sets aside manifest rows that make no record). Per episode the worker takes the task's
environment from its `WorkerContext` and runs `process_episode` with the stored VLM answer
(vlm_step.py); the runner then writes `_done/<suite>__<task>__<episode_id>.done` holding
`{"status", "reason", "inputs"}`, `inputs` being `layout.fingerprint` taken before the
files were read, so a changed input is done again (`forget` drops its old VLM answer and
scene first). A per-episode EpisodeError has already become a quarantine entry (marked
done); any other error of one episode (not a FatalError) is set aside as an
`episode_error` entry without a marker, so the next run tries it again. Episodes of one
task share one shard (one environment build).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.labelers.base import Onset
from pipeline.records import EpisodeRecord, QuarantineEntry, QuarantineReason
from pipeline.runner import Stage, UnitResult, WorkerContext
from pipeline.layout import RunLayout, Stage2Layout
from pipeline.stage2.layout import fingerprint, unit_id


@dataclass
class Stage2(Stage[EpisodeRecord]):
    cfg: Config
    name: str = "stage 2"
    counts: dict[str, int] = field(default_factory=dict)  # failed / successes, set by `units`

    @property
    def root(self) -> Path:
        return RunLayout.of(self.cfg).stage2.root

    @property
    def paths(self) -> Stage2Layout:
        return RunLayout.of(self.cfg).stage2

    def units(self, cfg: Config) -> list[EpisodeRecord]:
        from pipeline.stage2.pending import read_failures

        failed, n_failed, n_success = read_failures(cfg)
        self.counts = {"failed": n_failed, "successes": n_success}
        return failed

    def unit_id(self, rec: EpisodeRecord) -> str:
        return unit_id(rec)

    def fingerprint(self, rec: EpisodeRecord) -> dict[str, str]:
        return fingerprint(RunLayout.of(self.cfg).stage1.root, rec)

    def forget(self, rec: EpisodeRecord) -> None:
        from pipeline.stage2.pending import forget

        forget(self.paths, rec)  # its inputs changed since: the stored answers are about old files

    def group(self, rec: EpisodeRecord):
        return rec.suite, rec.task

    def shards(self, units: list[EpisodeRecord], workers: int) -> list[tuple[EpisodeRecord, ...]]:
        by_task: dict[tuple[str, str], list[EpisodeRecord]] = {}
        for rec in units:  # one shard per task, never split: the environment is built once per task
            by_task.setdefault(self.group(rec), []).append(rec)
        return [tuple(eps) for _, eps in sorted(by_task.items())]

    def _stored_onset(self, rec: EpisodeRecord) -> Onset | None:
        """The VLM step's answer for `rec` (None for simstate, which localizes in the worker)."""
        backend = self.cfg.stage2.vlm.backend
        if backend == "simstate":
            return None
        file = self.paths.abs(self.paths.vlm(rec))
        if not file.exists():
            return Onset(source=backend, reason=QuarantineReason.backend_error, detail="no stored VLM result")
        try:
            return Onset.model_validate_json(file.read_text())
        except ValueError as e:  # ValidationError included: this episode is set aside (episode_error), naming the file
            raise ValueError(f"{file}: not a stored VLM answer: {e}") from e

    def process(self, rec: EpisodeRecord, ctx: WorkerContext) -> UnitResult:
        from pipeline.sim import get_task
        from pipeline.stage2.episode import process_episode

        env = ctx.env(get_task(rec.suite, rec.task))
        vlm = self._stored_onset(rec)
        out = process_episode(env, rec, RunLayout.of(self.cfg).stage1.root, self.paths, self.cfg.stage2, vlm)
        return UnitResult(info={"status": out.status, "reason": out.reason}, ok=out.status == "scene",
                          status=out.status, reason=out.reason or None)

    def set_aside(self, rec: EpisodeRecord, error: Exception) -> UnitResult:
        paths = self.paths
        paths.abs(paths.localization(rec)).unlink(missing_ok=True)
        entry = QuarantineEntry(key=rec.key, stage="stage2", source="stage2",
                                reason=QuarantineReason.episode_error,
                                detail=f"{type(error).__name__}: {error}"[:2000])
        write_json(paths.abs(paths.quarantine(rec)), entry.model_dump(mode="json"))
        return UnitResult.set_aside(entry.reason, entry.detail)
