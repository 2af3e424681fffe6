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
The episodes run as a Stage (`Stage3`) through the Runner on the configured executor
(`inline`, `local`, `ray`): the runner checks and writes the done markers; each worker
opens its own queue engine and builds its own characterizer.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console

from pipeline.atomic import write_json
from pipeline.config import Config, save_resolved
from pipeline.errors import FatalError
from pipeline.executors import make_executor
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
    """Stage 3 as a Stage: one unit per episode, characterized in batches of BATCH, each
    enqueued then finished. The stage holds only the config: each worker builds its own
    review-database engine and characterizer (`WorkerContext.helper`), so the stage pickles
    and runs on every executor. Concurrent workers write one SQLite file safely (WAL, busy
    timeout, IMMEDIATE transactions: `review.db.make_engine`); enqueueing is idempotent."""

    cfg: Config
    name: str = "stage 3"
    batch_size: int = BATCH  # episodes per characterizer call, and per shard with simstate

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
        if self.cfg.stage3.vlm.backend != "simstate":  # one client: `max_in_flight` bounds the server's load
            return [tuple(units)] if units else []
        n = self.batch_size
        return [tuple(units[i:i + n]) for i in range(0, len(units), n)]

    def engine(self, ctx: WorkerContext):
        """This worker's review-database engine (the main process migrated the schema first)."""
        return ctx.helper(f"stage3 engine {self.root}", lambda: engine_for(self.cfg), close=lambda e: e.dispose())

    def characterizer(self, ctx: WorkerContext):
        return ctx.helper(f"stage3 characterizer {self.root} {self.sig}",
                          lambda: make_characterizer(self.cfg.stage3.vlm, Path(self.cfg.out)))

    def process(self, unit: Unit, ctx: WorkerContext) -> UnitResult:
        [(_, result)] = self.batch([unit], ctx)
        return result

    def stream(self, units: list[Unit], ctx: WorkerContext, finish) -> None:
        for start in range(0, len(units), self.batch_size):
            batch = units[start:start + self.batch_size]
            for unit in batch:
                ctx.emit(self.event("started", unit))
            for unit, result in self.batch(batch, ctx):
                finish(unit, result)

    def batch(self, units: list[Unit], ctx: WorkerContext) -> list[tuple[Unit, UnitResult]]:
        """Characterize `units` in one call, store and enqueue each; results in order."""
        run_dir, cfg = Path(self.cfg.out), self.cfg
        hz, fps = cfg.stage1.rollout.control_hz, float(cfg.stage1.video.fps)
        inputs = [self.fingerprint(u) for u in units]  # before reading the files
        locs = [u.localization for u in units if u.localization is not None]
        characterize = self.characterizer(ctx) if locs else None
        got = characterize.characterize(locs) if characterize is not None else []
        if len(got) != len(locs):  # a lost outcome would shift every later one onto the wrong episode
            raise FatalError(f"stage 3: characterizer {characterize.name} gave {len(got)} outcomes "
                             f"for {len(locs)} localizations")
        outcomes = iter(got)
        out = []
        for unit, fp in zip(units, inputs, strict=True):
            outcome = next(outcomes) if unit.localization is not None else unit.quarantine
            status = _store(run_dir, cfg, self.engine(ctx), unit, outcome, hz, fps)
            info = {"key": unit.key, "characterizer": _describe(cfg)}
            if status == "set_aside_bad_proposal":  # the main process counts it from the marker
                info["quarantine"] = unit.quarantine.model_dump(mode="json")
            out.append((unit, UnitResult(info=info, status=status, ok=status == "characterized", inputs=fp)))
        return out


def run(cfg: Config) -> dict:
    layout = RunLayout.of(cfg)
    run_dir, s3 = layout.root, layout.stage3.root
    save_resolved(cfg, s3)
    console = Console()
    runner = Runner(make_executor(cfg.executor), console=console)
    engine_for(cfg).dispose()  # create and migrate the queue here, once, before the workers open it
    stage = Stage3(cfg)
    units = stage.units(cfg)
    todo = runner.pending(stage, units)
    if todo:  # its items show the videos to reviewers (and a VLM characterizer watches them)
        require_current_frames(run_frame_tables(cfg), "stage 3")
    counts: Counter = Counter(skipped=len(units) - len(todo))
    if not units:
        console.print(f"[yellow]stage 3: nothing to do[/yellow]: no stage-2 outputs under {layout.stage2.root}")
    stage.name = f"stage 3: characterize + enqueue ({cfg.stage3.vlm.backend})"
    counts.update(runner.execute(stage, todo).statuses)
    faults = _faults(stage, units)
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


def _faults(stage: Stage3, units: list[Unit]) -> list[QuarantineEntry]:
    """The set-aside units, in order: the input faults `collect` found, and the proposals the
    queue refused (recorded in their done markers by whichever worker ran them)."""
    from pipeline.runner.runner import finished

    done = finished(stage, units)
    out = []
    for u in units:
        if u.quarantine and u.quarantine.stage == "stage3" and u.quarantine.reason in INPUT_FAULTS:
            out.append(u.quarantine)
        elif refused := done.get(u.unit_id, {}).get("quarantine"):
            out.append(QuarantineEntry.model_validate(refused))
    return out


def _describe(cfg: Config) -> str:
    from pipeline.labelers.registry import describe

    return describe(cfg.stage3.vlm)


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
