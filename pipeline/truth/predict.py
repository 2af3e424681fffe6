"""`recover bench-localize`'s predictions: the localizer (and characterizer) under test run
on each scored episode as a `Stage` (`BenchStage`) by the `Runner` on the configured
executor, one unit per episode.

Every localizer and characterizer is the one stages 2 and 3 use, built by
`pipeline.labelers.registry` in each worker (`WorkerContext.helper`) and called through the
`Localizer` / `Characterizer` protocols:
- simstate: the simstate localizer on the evidence for the onset (the stage-2 evidence file
  when there is one, else measured from the logged states on the worker's environment;
  nothing is written to stage2/), then the simstate characterizer for level and category.
  Episodes of one task share a shard, never split (one environment build per task).
- openai | transformers: one model is asked to localize, then to characterize at its own
  onset, `BATCH` episodes per request round; every episode runs in one shard, so one client
  (its `max_in_flight`) or one loaded model serves them all. An unusable answer is a miss,
  with its quarantine reason.
A unit's `Prediction` is its done marker's info (`<bench folder>/_done/<unit>.done`), recorded
with what it was computed from: the episode's stage-1 files (`stage2.layout.fingerprint`),
the stored evidence's size + mtime, the stage-2 config, the VLM's prompt files' digest
(`registry.describe`) and a hash of the labelers' source code, so a rerun after a change of rules, thresholds or prompts predicts again and an
unchanged episode is not asked twice. Unusable evidence (a missing or truncated file) is a
miss with the reason; anything else that fails one episode sets it aside with the reason.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from functools import cached_property
from pathlib import Path

from pipeline.config import Config
from pipeline.errors import EpisodeError
from pipeline.labelers.base import Characterizer, Episode
from pipeline.layout import RunLayout, Stage1Layout
from pipeline.records import Characterization, EpisodeRecord, Localization, Phases
from pipeline.runner import Stage, UnitResult, WorkerContext

BATCH = 32  # episodes per VLM request round


@dataclass
class Prediction:
    key: str
    fail_step: int | None = None
    level: str | None = None
    category: str | None = None
    reason: str = ""  # why a value is missing (no_failure_found, a quarantine reason, ...)


def _episode(stage1: Path, rec: EpisodeRecord, evidence=None) -> Episode:
    """What a localizer sees of `rec`: its agentview video and frame table (a missing video is
    the localizer's `no_video`), and the evidence when the caller measured it."""
    import pyarrow.parquet as pq

    layout = Stage1Layout(stage1)
    folder, video = layout.episode(rec).dir, layout.video(rec, "agentview")
    if evidence is not None or video is None or not video.is_file():
        return Episode(rec, folder, evidence=evidence)
    fp = layout.episode(rec).frames
    return Episode(rec, folder, video, pq.read_table(fp) if fp.is_file() else None)


def _stub_localization(rec: EpisodeRecord, step: int, time_s: float, source: str, phases: Phases | None = None,
                       events=(), scene_step: int | None = None) -> Localization:
    """A Localization at the localizer's own onset (no scene is written: only the characterizer reads it,
    with the step stage 2 would snapshot, `scene_step`; the onset when not known)."""
    phases = phases or Phases(pre=(0, step), during=(step, min(step + 1, rec.steps + 1)),
                              post=(min(step + 1, rec.steps + 1), rec.steps + 1))
    return Localization(key=rec.key, suite=rec.suite, task=rec.task, episode_id=rec.episode_id,
                        instruction=rec.instruction, source=source, fail_step=step, fail_time_s=time_s,
                        phases=phases, scene_step=scene_step, scene_bddl="", scene_state="", events=list(events))


def _characterize(characterizer: Characterizer, out: dict[str, Prediction], locs: list[Localization]) -> None:
    for loc, got in zip(locs, characterizer.characterize(locs), strict=True):
        if isinstance(got, Characterization):
            out[loc.key].level, out[loc.key].category = got.recovery_level.value, got.failure_category.value
        else:
            out[loc.key].reason = f"characterize: {got.reason}"


def labelers_code() -> str:
    """A hash of the source the predictions depend on beyond the config (rules, prompts' code)."""
    import pipeline.evidence
    import pipeline.labelers
    import pipeline.stage2.phases

    labelers = Path(pipeline.labelers.__file__).parent
    h = hashlib.sha256()
    for p in [*sorted(labelers.rglob("*.py")), Path(pipeline.evidence.__file__), Path(pipeline.stage2.phases.__file__)]:
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    return h.hexdigest()[:16]


class _Labelers:
    """One worker's localizer and characterizer. simstate's characterizer reads the evidence
    the worker measured (`evidence`); a VLM's shares the localizer's model."""

    def __init__(self, cfg: Config, backend: str):
        from pipeline.labelers.registry import make_characterizer, make_localizer

        vlm_cfg = cfg.stage2.vlm.model_copy(update={"backend": backend})
        self.evidence: dict[str, object] = {}
        self.localizer = make_localizer(vlm_cfg)
        if backend == "simstate":
            self.characterizer = make_characterizer(vlm_cfg, Path(cfg.out), evidence_for=lambda loc: self.evidence[loc.key])
        else:
            self.characterizer = make_characterizer(vlm_cfg, Path(cfg.out), backend=self.localizer.backend)

    def close(self) -> None:
        self.localizer.close()  # a VLM characterizer shares its backend


@dataclass
class BenchStage(Stage[EpisodeRecord]):
    """One unit per scored episode; its Prediction is the marker's info (module docstring)."""

    cfg: Config
    localizer: str
    records: list[EpisodeRecord]
    folder: Path  # the report folder; markers in its _done/
    name: str = "bench-localize"
    code: str = field(default_factory=labelers_code)  # taken once, in the main process

    @property
    def root(self) -> Path:
        return self.folder

    @property
    def vlm(self) -> bool:
        return self.localizer != "simstate"

    def units(self, cfg: Config | None = None) -> list[EpisodeRecord]:
        return self.records

    @cached_property
    def prompts(self) -> str:
        """The VLM's model, prompt version and prompt files' digest (an edited prompt file
        predicts again); simstate asks no prompt."""
        from pipeline.labelers.registry import describe

        return describe(self.cfg.stage2.vlm.model_copy(update={"backend": self.localizer}))

    def unit_id(self, rec: EpisodeRecord) -> str:
        from pipeline.stage2.layout import unit_id

        return unit_id(rec)

    def fingerprint(self, rec: EpisodeRecord) -> dict:
        from pipeline.atomic import file_stamp
        from pipeline.stage2.layout import fingerprint

        layout = RunLayout.of(self.cfg)
        stored = layout.stage2.abs(layout.stage2.evidence(rec))
        config = json.dumps([self.localizer, self.cfg.stage2.model_dump(mode="json"), self.prompts], sort_keys=True)
        return {"episode": fingerprint(layout.stage1.root, rec),
                "evidence": file_stamp(stored) if not self.vlm and stored.is_file() else None,
                "config": hashlib.sha256(config.encode()).hexdigest()[:16], "code": self.code}

    def group(self, rec: EpisodeRecord):
        return rec.suite, rec.task

    def shards(self, units: list[EpisodeRecord], workers: int) -> list[tuple[EpisodeRecord, ...]]:
        if self.vlm:  # one client or one loaded model for every episode
            return [tuple(units)] if units else []
        by_task: dict[tuple[str, str], list[EpisodeRecord]] = {}
        for rec in units:  # one shard per task, never split (as stage 2): measuring evidence is cheap, a build is not
            by_task.setdefault(self.group(rec), []).append(rec)
        return [tuple(recs) for _, recs in sorted(by_task.items())]

    def labelers(self, ctx: WorkerContext) -> _Labelers:
        return ctx.helper(f"bench {self.localizer} {self.cfg.out}", lambda: _Labelers(self.cfg, self.localizer))

    def process(self, rec: EpisodeRecord, ctx: WorkerContext) -> UnitResult:
        [pred] = self.predict_vlm([rec], ctx) if self.vlm else [self.predict_simstate(rec, ctx)]
        return _result(pred)

    def stream(self, units: list[EpisodeRecord], ctx: WorkerContext, finish) -> None:
        if not self.vlm:
            return super().stream(units, ctx, finish)
        for start in range(0, len(units), BATCH):
            batch = units[start:start + BATCH]
            inputs = [self.fingerprint(r) for r in batch]  # before the files are read
            for rec in batch:
                ctx.emit(self.event("started", rec))
            for rec, pred, fp in zip(batch, self.predict_vlm(batch, ctx), inputs, strict=True):
                finish(rec, _result(pred).model_copy(update={"inputs": fp}))

    def set_aside(self, rec: EpisodeRecord, error: Exception) -> UnitResult:
        return UnitResult.set_aside(type(error).__name__, str(error)[:2000])

    def predict_simstate(self, rec: EpisodeRecord, ctx: WorkerContext) -> Prediction:
        from pipeline.evidence import compute_evidence, read_evidence
        from pipeline.sim import get_task
        from pipeline.stage2.layout import load_episode
        from pipeline.stage2.phases import settled_step, split_phases

        layout, tools = RunLayout.of(self.cfg), self.labelers(ctx)
        stored = layout.stage2.abs(layout.stage2.evidence(rec))
        try:
            if stored.is_file():
                ev = read_evidence(stored)
            else:  # no stage 2 yet: measure the logged states (nothing is written)
                ep = load_episode(layout.stage1.root, rec)
                env = ctx.env(get_task(rec.suite, rec.task))
                ev = compute_evidence(env, ep.states, ep.steps["action"][:, 6], rec.control_hz)
        except (EpisodeError, OSError, ValueError) as e:  # a missing or unreadable file: this episode is a miss
            return Prediction(rec.key, reason=f"evidence: {type(e).__name__}: {e}")
        [onset] = tools.localizer.localize([_episode(layout.stage1.root, rec, ev)])
        if onset.fail_step is None:
            return Prediction(rec.key, reason=onset.reason or "no_failure_found")
        step = min(onset.fail_step, len(ev) - 1)
        s2 = self.cfg.stage2
        loc = _stub_localization(rec, step, step / rec.control_hz, tools.localizer.name,
                                 split_phases(ev, step, s2.settle_speed_mps, s2.settle_steps), onset.events,
                                 settled_step(ev, step, s2.settle_speed_mps, s2.settle_steps))
        out = {rec.key: Prediction(rec.key, step)}
        tools.evidence[rec.key] = ev
        try:
            _characterize(tools.characterizer, out, [loc])
        finally:
            del tools.evidence[rec.key]
        return out[rec.key]

    def predict_vlm(self, batch: list[EpisodeRecord], ctx: WorkerContext) -> list[Prediction]:
        from pipeline.stage2.phases import step_for_time

        stage1 = RunLayout.of(self.cfg).stage1.root
        episodes = [_episode(stage1, rec) for rec in batch]
        if not any(e.video is not None for e in episodes):  # no model is loaded for nothing to watch
            return [Prediction(rec.key, reason="no_video") for rec in batch]
        tools = self.labelers(ctx)
        out: dict[str, Prediction] = {}
        located = []
        for ep, onset in zip(episodes, tools.localizer.localize(episodes), strict=True):
            rec = ep.record
            if not onset.found:
                out[rec.key] = Prediction(rec.key, reason=onset.reason or "backend_error")
                continue
            step = step_for_time(onset.fail_time_s, ep.frames, rec.steps, rec.control_hz)
            out[rec.key] = Prediction(rec.key, step)
            located.append(_stub_localization(rec, step, onset.fail_time_s, tools.localizer.name))
        if located:
            _characterize(tools.characterizer, out, located)
        return [out[rec.key] for rec in batch]

    def predictions(self) -> dict[str, Prediction]:
        """The current Prediction of every episode that has one, by episode key."""
        from pipeline.runner.runner import finished

        return {info["key"]: Prediction(**{k: info[k] for k in ("key", "fail_step", "level", "category", "reason")})
                for info in finished(self, self.records).values()}


def _result(pred: Prediction) -> UnitResult:
    found = pred.fail_step is not None
    return UnitResult(info=asdict(pred), ok=found, status="localized" if found else "miss")
