"""Stage 2: localize failure onsets, split phases, write recovery scenes and histories.

Input: stage 1's run layout (pipeline/records.py): `stage1/episodes.parquet` and each
episode's states.npy / steps.parquet / frames.parquet / videos. Successful episodes are
skipped. Every failed episode ends with EITHER a scene pair (+ history + Localization) OR a
QuarantineEntry saying why -- never nothing.

Output layout, under `<run.output_dir>/stage2/`:
    config.resolved.yaml
    evidence/<suite>/<task>/<episode_id>.parquet       per-step simulator evidence (EVIDENCE_SCHEMA)
    localizations/<suite>/<task>/<episode_id>.json     one Localization per localized episode
    quarantine/<suite>/<task>/<episode_id>.json        one QuarantineEntry (reason, raw text)
    vlm/<suite>/<task>/<episode_id>.json               the VLM's stored answer (VLM backends only)
    vlm/_done/<suite>__<task>__<episode_id>.done       the VLM step's markers (the runner's)
    selected_bddl_scenes_<suite>/<task>/episode_<episode_id>/
        step_<NNNN>.bddl                               the task's BDDL, one declaration line per type
        step_<NNNN>_sim_state.npy                      flattened MuJoCo state, first settled step >= onset
        step_<NNNN>_history.npz                        pre-failure window: states, robot, actions
        step_<NNNN>_history_frames.npz                 its rendered frames (not byte-reproducible)
    localizations.parquet                              all Localizations, compiled
    agreement.json, agreement.png                      VLM vs simstate (when a VLM ran)
    summary.json
    _done/<suite>__<task>__<episode_id>.done           completion markers, written last; they record
                                                       the inputs' fingerprint (see stage.py)

Flow: (1) with a VLM backend, ask it about every pending episode (vlm_step's `VLMStep`, a
Stage on the Runner: one shard, `max_in_flight` concurrent requests); (2) the executor runs one shard per task (the env is
built once per task): evidence -> simstate -> onset -> phases -> scene -> history -> record;
(3) compile the reports. The episodes run as a Stage (stage.py) through the Runner. Resumable: episodes with a done marker are skipped unless their
inputs changed since (the marker records size + mtime of the stage-1 files and a hash of the
manifest row), so a fixed file is picked up by the next run; reports are rebuilt from the
per-episode files every time. Bad input never stops the stage: a manifest row that makes no
record, or a truncated / inconsistent episode file, becomes a quarantine entry naming the
file, the field and the reason; the summary counts them (`set_aside`). Only an unreadable
manifest as a whole is fatal.
"""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from pipeline.config import Config, save_resolved
from pipeline.executors import make_executor
from pipeline.runner import Runner
from pipeline.layout import RunLayout
from pipeline.stage2.report import write_reports
from pipeline.stage2.stage import Stage2

console = Console()


def run(cfg: Config) -> dict:
    paths = RunLayout.of(cfg).stage2
    paths.root.mkdir(parents=True, exist_ok=True)
    save_resolved(cfg, paths.root)
    stage = Stage2(cfg)
    runner = Runner(make_executor(cfg.executor), console=console)
    todo = runner.pending(stage, stage.units(cfg))
    n_failed, n_success = stage.counts["failed"], stage.counts["successes"]
    console.print(f"stage 2: {n_failed} failed episodes ({n_success} successes skipped), "
                  f"{len(todo)} to do, localizer [bold]{cfg.stage2.vlm.backend}[/bold]")
    if todo and cfg.stage2.vlm.backend != "simstate":
        from pipeline.stage2.vlm_step import run_vlm

        run_vlm(cfg, todo, console)
    if todo:
        runner.execute(stage, todo)
    summary = write_reports(paths.root)
    _print_summary(summary, n_failed)
    if summary["set_aside"]:
        console.print(f"[yellow]stage 2: {summary['set_aside']} set aside for bad input[/yellow] "
                      "(quarantined with file, field and reason; fix the file and rerun to retry):")
        for q in summary["input_faults"][:20]:
            console.print(f"  {q['key']}: {q['reason']} {q['file']} field {q['field']}")
    return summary


def _print_summary(summary: dict, n_failed: int) -> None:
    table = Table(title=f"stage 2: {n_failed} failed episodes")
    table.add_column("outcome")
    table.add_column("episodes", justify="right")
    table.add_row("scene pair", str(summary["scenes"]))
    for reason, n in sorted(summary["quarantine_reasons"].items()):
        table.add_row(f"quarantined: {reason}", str(n))
    for kind, n in sorted(summary["onset_kinds"].items(), key=lambda kv: str(kv[0])):
        table.add_row(f"  onset event: {kind or 'vlm'}", str(n))
    agr = summary.get("agreement")
    if agr and agr.get("n"):
        table.add_row("VLM vs simstate MAE (s)", f"{agr['mae_s']:.2f}")
        table.add_row("within 0.5 s / 1 s", f"{agr['within_0_5s']:.0%} / {agr['within_1s']:.0%}")
    console.print(table)
