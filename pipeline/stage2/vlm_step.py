"""The one place stage 2 calls a VLM: the `openai` / `transformers` localizer of
`pipeline.labelers` (built by `registry.make_localizer`, used through the Localizer protocol).

Input: the failed episodes still to do and the run config. For each episode the backend
is asked when the failure began (agentview video + instruction + stage 1's frame table, so
times are true times); the answer goes through the loss-free parser. Output, per episode,
an `Onset` (pipeline.labelers.base) stored as `stage2/vlm/<suite>/<task>/<episode_id>.json`:
    {"source", "model", "prompt_name", "prompt_hash", "raw_text", "latency_s",
     "fail_time_s"}                      -- a usable answer, or
    {..., "reason", "detail"}           -- the parser's / backend's quarantine reason.
The episode workers read these files (pipeline/stage2/stage.py).

The requests run as a Stage (`VLMStep`, one unit per episode) by the `Runner` on the
configured executor, before the episodes' own stage: every episode in one shard, so one
client (its `max_in_flight`) or one loaded model serves them all, asked `BATCH` at a time
so a crash loses at most one batch. The runner writes each episode's marker
(`stage2/vlm/_done/<unit>.done`) after its answer, with the episode's stage-1 inputs
(`layout.fingerprint`) and the localizer (`registry.describe`: backend, model, prompt
version and the prompt files' digest): an episode answered for its current files by the
same model and prompt is not asked again.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from rich.console import Console

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.labelers.base import Episode, Onset
from pipeline.layout import RunLayout, Stage2Layout
from pipeline.records import EpisodeRecord, QuarantineReason
from pipeline.runner import Stage, UnitResult, WorkerContext

BATCH = 32


@dataclass
class VLMStep(Stage[EpisodeRecord]):
    """The VLM's answers about `episodes`, stored for stage 2's episode workers."""

    cfg: Config
    episodes: list[EpisodeRecord]
    name: str = "stage 2: VLM localization"

    @property
    def paths(self) -> Stage2Layout:
        return RunLayout.of(self.cfg).stage2

    @property
    def root(self) -> Path:
        return self.paths.vlm_dir

    def units(self, cfg: Config | None = None) -> list[EpisodeRecord]:
        return self.episodes

    def unit_id(self, rec: EpisodeRecord) -> str:
        from pipeline.stage2.layout import unit_id

        return unit_id(rec)

    def fingerprint(self, rec: EpisodeRecord) -> dict[str, str]:
        from pipeline.stage2.layout import fingerprint

        # the localizer too: another model or prompt (version or text) asks again
        return {**fingerprint(RunLayout.of(self.cfg).stage1.root, rec), "localizer": self.localizer_id}

    @cached_property
    def localizer_id(self) -> str:
        from pipeline.labelers.registry import describe

        return describe(self.cfg.stage2.vlm)

    def forget(self, rec: EpisodeRecord) -> None:
        self.paths.abs(self.paths.vlm(rec)).unlink(missing_ok=True)  # an answer about the old video

    def shards(self, units: list[EpisodeRecord], workers: int) -> list[tuple[EpisodeRecord, ...]]:
        return [tuple(units)] if units else []  # one client or one loaded model for every episode

    def localizer(self, ctx: WorkerContext):
        from pipeline.labelers.registry import make_localizer

        return ctx.helper(f"stage2 vlm {self.root}", lambda: make_localizer(self.cfg.stage2.vlm))

    def process(self, rec: EpisodeRecord, ctx: WorkerContext) -> UnitResult:
        [(_, result)] = self.ask([rec], ctx)
        return result

    def stream(self, units: list[EpisodeRecord], ctx: WorkerContext, finish) -> None:
        for start in range(0, len(units), BATCH):
            batch = units[start:start + BATCH]
            inputs = [self.fingerprint(r) for r in batch]  # before the files are read
            for rec in batch:
                ctx.emit(self.event("started", rec))
            for (rec, result), fp in zip(self.ask(batch, ctx), inputs, strict=True):
                finish(rec, result.model_copy(update={"inputs": fp}))

    def ask(self, batch: list[EpisodeRecord], ctx: WorkerContext) -> list[tuple[EpisodeRecord, UnitResult]]:
        """Ask the VLM about `batch` in one round; store each answer; results in order."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        stage1, paths = RunLayout.of(self.cfg).stage1, self.paths
        answers: dict[str, Onset] = {}
        episodes: list[Episode] = []
        for rec in batch:
            folder = stage1.episode(rec).dir
            video = stage1.video(rec, "agentview")
            if video is None or not video.exists():
                episodes.append(Episode(rec, folder))  # the localizer answers no_video
                continue
            fp = stage1.episode(rec).frames
            try:
                frames = pq.read_table(fp) if fp.exists() else None
            except (pa.ArrowException, OSError) as e:  # truncated: the episode worker sets it aside
                answers[rec.key] = Onset(source=self.cfg.stage2.vlm.backend, reason=QuarantineReason.stage1_bad_frames,
                                         detail=f"{fp}: unreadable ({e})")
                continue
            episodes.append(Episode(rec, folder, video, frames))
        if episodes:
            for ep, onset in zip(episodes, self.localizer(ctx).localize(episodes), strict=True):
                answers[ep.record.key] = onset
        out = []
        for rec in batch:
            onset = answers[rec.key]
            write_json(paths.abs(paths.vlm(rec)), onset.stored())
            status = "answered" if onset.found else str(onset.reason)
            out.append((rec, UnitResult(info={"status": status}, ok=onset.found, status=status)))
        return out


def run_vlm(cfg: Config, episodes: list[EpisodeRecord], console: Console | None = None) -> int:
    """Ask the VLM about every episode of `episodes` not answered for its current inputs, on
    the configured executor; return how many were asked."""
    from pipeline.executors import make_executor
    from pipeline.rendered import require_current_frames
    from pipeline.runner import Runner

    stage = VLMStep(cfg, episodes)
    runner = Runner(make_executor(cfg.executor), console=console)
    todo = runner.pending(stage, episodes)
    if not todo:
        return 0
    stage1 = RunLayout.of(cfg).stage1
    require_current_frames([stage1.episode(r).frames for r in todo], f"stage 2's {cfg.stage2.vlm.backend} localizer")
    runner.execute(stage, todo, done_before=len(episodes) - len(todo))
    return len(todo)
