"""Stage 3: characterize every localized failure and fill the human review queue.

Inputs: stage-2 localizations and quarantine entries (see `inputs`), stage-1 media.
Outputs (run folder):
  stage3/characterizations/<suite>/<task>/<episode_id>.json   records.Characterization
  stage3/quarantine/<suite>/<task>/<episode_id>.json          records.QuarantineEntry (stage3)
  stage3/review.sqlite (or `stage3.db_url`)                   one queue item per episode
  stage3/_done/<suite>__<task>__<episode_id>__<characterizer>.done   written last, per episode
  stage3/summary.json, stage3/config.resolved.yaml
Invariants: every stage-2 outcome enters the queue: a quarantined stage-2 output, or a
characterization that failed, becomes an item marked quarantined (people supply the
values); rerunning skips finished episodes, and enqueueing is idempotent, so a crash
between the queue write and the done-marker loses and duplicates nothing. Done-markers name
the characterizer (backend, model, prompt version) and record the unit's inputs (a hash of
its stage-2 file, its evidence's size + mtime): a new characterizer or a corrected input
characterizes again, and a changed proposal enters the queue as a new revision (final
records stay untouched). A stage-2 file stage 3 cannot use (see `inputs.collect`: NaN,
negative or too late fail_time_s, a repeated key, no parse) is set aside as a stage-3
QuarantineEntry naming file, field and reason and queued as a quarantined item, and so is
an episode whose proposal or review context the queue refuses (`bad_proposal`); the summary
counts them (`set_aside`) and prints "N set aside". The exit status stays 0: set-aside
episodes are per-episode outcomes (pipeline.errors.EpisodeError), visible in the summary.
The episodes run as a Stage (`Stage3`) through the Runner, in this process (inline
executor): the runner checks and writes the done markers.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console

from pipeline.atomic import write_json
from pipeline.config import Config, save_resolved
from pipeline.errors import FatalError
from pipeline.executors.local import InlineExecutor
from pipeline.layout import RunLayout, parse_key
from pipeline.records import Characterization, QuarantineEntry, QuarantineReason
from pipeline.rendered import require_current_frames, run_frame_tables
from pipeline.review.db import write_session
from pipeline.review.enqueue import enqueue
from pipeline.review.proposal import VALUE_FIELDS, InvalidProposal
from pipeline.review.server import engine_for
from pipeline.labelers.registry import make_characterizer
from pipeline.runner import Runner, Stage, UnitResult, WorkerContext
from pipeline.stage3.inputs import INPUT_FAULTS, UNREADABLE, Unit, collect, context, fingerprint, warn_unreadable

BATCH = 16


def proposal_for(unit: Unit, ch: Characterization | None, q: QuarantineEntry | None) -> dict:
    loc = unit.localization
    localizer = ({"source": loc.source, "model": loc.model, "prompt_name": loc.prompt_name,
                  "prompt_hash": loc.prompt_hash} if loc else
                 {"source": q.source, "model": q.model, "prompt_name": q.prompt_name, "prompt_hash": q.prompt_hash})
    char = ({"source": ch.source, "model": ch.model, "prompt_name": ch.prompt_name, "prompt_hash": ch.prompt_hash}
            if ch else ({"source": q.source, "model": q.model, "prompt_name": q.prompt_name,
                         "prompt_hash": q.prompt_hash} if q and q.stage == "stage3" else {}))
    return {
        "fail_time_s": loc.fail_time_s if loc else None,
        "fail_step": loc.fail_step if loc else None,
        "recovery_level": ch.recovery_level.value if ch else None,
        "failure_category": ch.failure_category.value if ch else None,
        "recovery_action": ch.recovery_action if ch else None,
        "localizer": localizer,
        "characterizer": char,
        # the version shown beside the suggestion and written to the audit log
        "source": (ch.source if ch else char.get("source")) or localizer.get("source"),
        "model": (ch.model if ch else char.get("model")) or localizer.get("model"),
        "prompt_name": (ch.prompt_name if ch else char.get("prompt_name")) or localizer.get("prompt_name"),
        "prompt_hash": (ch.prompt_hash if ch else char.get("prompt_hash")) or localizer.get("prompt_hash"),
    }


@dataclass
class Stage3(Stage[Unit]):
    """Stage 3 as a Stage, run in this process (no simulator; one queue engine): one shard of
    every pending episode, characterized in batches of BATCH, each enqueued then finished."""

    cfg: Config
    engine: Any
    characterize: Any  # the Characterizer (pipeline.labelers), None with nothing to characterize
    name: str = "stage 3"

    def __post_init__(self):
        self.sig = _signature(self.cfg)

    @property
    def root(self) -> Path:
        return RunLayout.of(self.cfg).stage3.root

    def units(self, cfg: Config) -> list[Unit]:
        return collect(Path(cfg.out))

    def marker_id(self, unit: Unit) -> str:
        return f"{unit.unit_id}__{self.sig}"  # names the characterizer: a new one characterizes again

    def fingerprint(self, unit: Unit) -> str:
        return fingerprint(Path(self.cfg.out), unit)

    def shards(self, units: list[Unit], workers: int) -> list[tuple[Unit, ...]]:
        return [tuple(units)] if units else []

    def process(self, unit: Unit, ctx: WorkerContext) -> UnitResult:
        raise NotImplementedError("stage 3 characterizes in batches: see stream")

    def stream(self, units: list[Unit], ctx: WorkerContext, finish) -> None:
        run_dir, cfg = Path(self.cfg.out), self.cfg
        hz, fps = cfg.stage1.rollout.control_hz, float(cfg.stage1.video.fps)
        for start in range(0, len(units), BATCH):
            batch = units[start:start + BATCH]
            inputs = [self.fingerprint(u) for u in batch]  # before reading the files
            locs = [u.localization for u in batch if u.localization is not None]
            got = self.characterize.characterize(locs) if locs else []
            if len(got) != len(locs):  # a lost outcome would shift every later one onto the wrong episode
                raise FatalError(f"stage 3: characterizer {self.characterize.name} gave {len(got)} outcomes "
                                 f"for {len(locs)} localizations")
            outcomes = iter(got)
            for unit, fp in zip(batch, inputs, strict=True):
                outcome = next(outcomes) if unit.localization is not None else unit.quarantine
                status = _store(run_dir, cfg, self.engine, unit, outcome, hz, fps)
                finish(unit, UnitResult(info={"key": unit.key, "characterizer": _describe(cfg)}, status=status,
                                        ok=status == "characterized", inputs=fp))


def run(cfg: Config) -> dict:
    layout = RunLayout.of(cfg)
    run_dir, s3 = layout.root, layout.stage3.root
    save_resolved(cfg, s3)
    console = Console()
    runner = Runner(InlineExecutor(), console=console)
    stage = Stage3(cfg, engine_for(cfg), None)
    units = stage.units(cfg)
    todo = runner.pending(stage, units)
    if todo:  # its items show the videos to reviewers (and a VLM characterizer watches them)
        require_current_frames(run_frame_tables(cfg), "stage 3")
    counts: Counter = Counter(skipped=len(units) - len(todo))
    if not units:
        console.print(f"[yellow]stage 3: nothing to do[/yellow]: no stage-2 outputs under {layout.stage2.root}")
    stage.characterize = make_characterizer(cfg.stage3.vlm, run_dir) if any(u.localization for u in todo) else None
    stage.name = f"stage 3: characterize + enqueue ({stage.characterize.name if stage.characterize else '-'})"
    try:
        counts.update(runner.execute(stage, todo).statuses)
    finally:
        if stage.characterize is not None:
            stage.characterize.close()
    faults = [u.quarantine for u in units if u.quarantine and u.quarantine.stage == "stage3"
              and u.quarantine.reason in (*INPUT_FAULTS, QuarantineReason.bad_proposal)]
    summary = {"episodes": len(units), **counts, "set_aside": len(faults),
               "input_faults": [{"key": q.key, "reason": q.reason, "file": q.file, "field": q.field} for q in faults]}
    write_json(layout.stage3.summary, summary)
    console.print(f"stage 3: { {k: v for k, v in summary.items() if k != 'input_faults'} }")
    if faults:  # queued as quarantined items (people supply the values), never as proposals
        console.print(f"[yellow]stage 3: {len(faults)} set aside[/yellow] for bad stage-2 input "
                      "(queued as quarantined items; fix the file and rerun to queue its values):")
        for q in faults[:20]:
            console.print(f"  {q.key}: {q.reason} {q.file} field {q.field}")
    return summary


def _describe(cfg: Config) -> str:
    v = cfg.stage3.vlm
    if v.backend == "simstate":
        return "simstate"
    model = v.openai.model if v.backend == "openai" else str(v.transformers.model_path)
    return f"{v.backend}:{model}:{v.prompt_version}:{v.language}"


def _signature(cfg: Config) -> str:
    """Short id of the characterizer: changing model or prompt re-characterizes every episode
    (an unchanged proposal is a no-op in the queue; a changed one becomes a new revision)."""
    import hashlib

    return hashlib.sha256(_describe(cfg).encode()).hexdigest()[:8]


def _store(run_dir: Path, cfg: Config, engine, unit: Unit, outcome, hz: int, fps: float) -> str:
    ch = outcome if isinstance(outcome, Characterization) else None
    q = outcome if isinstance(outcome, QuarantineEntry) else None
    s3 = RunLayout(run_dir).stage3
    char_file, q_file = s3.characterization(unit.key), s3.quarantine(unit.key)
    if ch is not None:
        write_json(char_file, ch.model_dump(mode="json"))
        q_file.unlink(missing_ok=True)  # an earlier characterizer's failure no longer applies
    elif q is not None and q.stage == "stage3":
        write_json(q_file, q.model_dump(mode="json"))
        char_file.unlink(missing_ok=True)
    instruction = unit.localization.instruction if unit.localization else unit.instruction or _instruction(run_dir, unit)
    proposal, ctx = proposal_for(unit, ch, q), context(run_dir, unit, hz, fps)
    try:
        with write_session(engine) as s:
            enqueue(s, key=unit.key, instruction=instruction, proposal=proposal, context=ctx,
                    required_reviews=cfg.stage3.reviews_per_item, quarantined=q is not None,
                    reason=f"{q.stage}:{q.reason}" if q else None, detail=q.detail if q else None)
    except InvalidProposal as e:  # set aside: queued without the bad values, people supply them
        q = unit.quarantine = _bad_proposal(run_dir, unit, ch, e)  # counted with the input faults
        write_json(q_file, q.model_dump(mode="json"))
        char_file.unlink(missing_ok=True)
        bare = {**proposal_for(unit, None, q), **dict.fromkeys(VALUE_FIELDS)}
        if e.field.startswith("context."):
            ctx = {"control_hz": hz, "fps": fps}
        with write_session(engine) as s:
            enqueue(s, key=unit.key, instruction=instruction, proposal=bare, context=ctx,
                    required_reviews=cfg.stage3.reviews_per_item, quarantined=True,
                    reason=f"{q.stage}:{q.reason}", detail=q.detail)
        return "set_aside_bad_proposal"
    if ch is not None:
        return "characterized"
    return "quarantined_stage3" if q is not None and q.stage == "stage3" else "quarantined_stage2"


def _bad_proposal(run_dir: Path, unit: Unit, ch: Characterization | None, e: InvalidProposal) -> QuarantineEntry:
    """The entry of an episode whose proposal or context the queue refused: the stage-2 file
    its values came from, and the field."""
    src = unit.source
    file = src.relative_to(run_dir).as_posix() if src is not None and src.is_relative_to(run_dir) else src
    return QuarantineEntry(key=unit.key, stage="stage3", source=ch.source if ch else "stage2",
                           reason=QuarantineReason.bad_proposal, detail=f"{file}: {e.detail}",
                           file=None if file is None else str(file), field=e.field)


def _instruction(run_dir: Path, unit: Unit) -> str:
    """A quarantined episode's instruction, from the stage-1 manifest when it is there."""
    manifest = RunLayout(run_dir).stage1.manifest
    if manifest.is_file():
        import pyarrow.parquet as pq

        suite, task, ep = parse_key(unit.key)
        try:
            rows = pq.read_table(manifest, columns=["suite", "task", "episode_id", "instruction"]).to_pylist()
        except UNREADABLE as e:  # an unreadable manifest is stage 2's to report; the key still names the task
            warn_unreadable(manifest, e, "the instruction is made from the task name")
            rows = []
        for row in rows:
            if (row["suite"], row["task"], row["episode_id"]) == (suite, task, ep) and row["instruction"]:
                return row["instruction"]
    return parse_key(unit.key)[1].replace("_", " ")
