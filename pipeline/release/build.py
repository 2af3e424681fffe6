"""`recover release`: assemble the scenario set from final reviewed annotations.

Inputs: the run folder (see `pipeline.release.sources`), the run folders of
`release.merge_runs` (other generators or seeds, same task selection) and `cfg.release`.
Output folder (default `<run>/release/`):
    selected_bddl_scenes_<suite>/<task>/episode_<id>/step_<NNNN>.bddl
                                                    step_<NNNN>_sim_state.npy
                                                    step_<NNNN>_history[...]   pre-failure history
    scenarios.parquet        the manifest (`pipeline.release.manifest`), certificate and split included
    split.json               the train/eval split's seed, share and counts (`pipeline.release.split`)
    README.md, figures/      the dataset card (`pipeline.release.card`) and the object positions
                             against the official init states (`pipeline.release.positions`)
    SHA256SUMS               every released file above (`sha256sum -c SHA256SUMS` works)
    _build/                  NOT part of the set: build time, quarantined annotations, certificates
                             (`_build/certificates/_done/`, see `pipeline.release.certify`),
                             `recover verify`'s results (`_build/verify/_done/`), object positions
                             per task model (`_build/positions/_done/`)
Invariants: released bytes depend only on the inputs and the config (no timestamps, no
absolute paths, sorted rows), so the same config and seed rebuild them byte for byte; scene
files are copied unchanged; files of scenes no longer released are removed.
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console

from pipeline.atomic import write_bytes, write_json, write_text
from pipeline.config import Config
from pipeline.errors import FatalError
from pipeline.layout import RESOLVED_CONFIG, RELEASE_BUILD, RELEASE_CARD, RELEASE_SPLIT, RELEASE_SUMS, SCENE_PREFIX, STATE_SUFFIX, ReleaseLayout, RunLayout
from pipeline.release.card import FIGURE, render_card, write_figure
from pipeline.release.positions import FIGURE as POSITIONS_FIGURE
from pipeline.release.positions import collect
from pipeline.release.positions import write_figure as write_positions_figure
from pipeline.release.certify import certify_all, scene_refs
from pipeline.release.manifest import MANIFEST_NAME, ScenarioRow, sha256_file, write_manifest
from pipeline.records import QuarantineEntry, QuarantineReason
from pipeline.release.sources import ReleaseItem, gather
from pipeline.release.split import apply as apply_split

if TYPE_CHECKING:
    from pipeline.executors import Executor

SUMS_NAME = RELEASE_SUMS
BUILD_DIR = RELEASE_BUILD


def release_dir(cfg: Config) -> Path:
    return RunLayout.of(cfg).release.root


def _copy(src: Path, dst: Path) -> None:
    if not dst.is_file() or dst.read_bytes() != src.read_bytes():
        write_bytes(dst, src.read_bytes())


def _place_files(item: ReleaseItem, out: Path) -> tuple[str, str, list[str]]:
    """Copy the scene pair and history; return their release-relative paths."""
    base = ReleaseLayout.scene_base(item.episode.key, item.step)
    bddl, state = f"{base}.bddl", f"{base}{STATE_SUFFIX}"
    _copy(item.scene_bddl, out / bddl)
    _copy(item.scene_state, out / state)
    history: list[str] = []
    h = item.history
    if h is not None and h.is_file():
        history.append(f"{base}_history{''.join(h.suffixes)}")
        _copy(h, out / history[-1])
    elif h is not None and h.is_dir():
        for f in sorted(p for p in h.rglob("*") if p.is_file()):
            history.append(f"{base}_history/{f.relative_to(h).as_posix()}")
            _copy(f, out / history[-1])
    return bddl, state, history


def _row(item: ReleaseItem, out: Path, bddl: str, state: str, history: list[str], state_dim: int) -> ScenarioRow:
    a, loc, ep = item.annotation, item.localization, item.episode
    char_hash = a.model_proposal.characterizer.get("prompt_hash")
    return ScenarioRow(
        suite=ep.suite, task=ep.task, instruction=ep.instruction, episode_id=ep.episode_id,
        init_state=ep.init_state, step=item.step, fail_time_s=a.fail_time_s, fail_step=a.fail_step,
        level=a.recovery_level, category=a.failure_category, recovery_action=a.recovery_action,
        policy=ep.policy,
        policy_kind=ep.policy_kind, generator=ep.generator, seed=ep.seed, localize_prompt_hash=loc.prompt_hash,
        characterize_prompt_hash=char_hash, reviewers=len({r.reviewer for r in a.reviews}),
        adjudicated=a.adjudication is not None, state_dim=state_dim,
        bddl_path=bddl, bddl_sha256=sha256_file(out / bddl), state_path=state,
        state_sha256=sha256_file(out / state), history_paths=history,
        history_sha256=[sha256_file(out / p) for p in history],
    )


def _remove_stale(out: Path, keep: set[str]) -> int:
    removed = 0
    for d in out.glob(f"{SCENE_PREFIX}*"):
        for p in sorted(d.rglob("*"), reverse=True):
            if p.is_file() and p.relative_to(out).as_posix() not in keep:
                p.unlink()
                removed += 1
            elif p.is_dir() and not any(p.iterdir()):
                p.rmdir()
    return removed


def _tasks_of(run: Path) -> dict | None:
    import yaml

    resolved = RunLayout(run).stage1.root / RESOLVED_CONFIG
    return (yaml.safe_load(resolved.read_text()) or {}).get("tasks") if resolved.is_file() else None


def gather_runs(cfg: Config) -> tuple[list[ReleaseItem], list[QuarantineEntry]]:
    """The release items of this run and of `release.merge_runs`: same task selection (from
    each run's resolved stage-1 config, where it has one), every episode key once."""
    runs = [Path(cfg.out)] + [Path(r) for r in cfg.release.merge_runs]
    items, skipped, origin = [], [], {}
    for run in runs:
        if not run.is_dir():
            raise FatalError(f"release.merge_runs: {run}: no such run folder")
        if run != runs[0] and (theirs := _tasks_of(run)) is not None and (ours := _tasks_of(runs[0])) is not None \
                and theirs != ours:
            raise FatalError(f"release.merge_runs: {run} selects other tasks than {runs[0]} (stage1/{RESOLVED_CONFIG}"
                             f" `tasks`: {theirs} vs {ours}); a merged release covers one task selection")
        got, left = gather(run, cfg.stage2)
        for it in got:
            key = it.annotation.key
            if key in origin:
                raise FatalError(f"release.merge_runs: episode {key} is in both {origin[key]} and {run}; give the "
                                 f"generators different names (stage1.policy.name) or seeds")
            origin[key] = run
        items += got
        skipped += left
    items.sort(key=lambda it: (it.episode.suite, it.episode.task, it.episode.episode_id))
    return items, skipped


def build(cfg: Config, console: Console | None = None, executor: Executor | None = None) -> list[ScenarioRow]:
    import numpy as np

    console = console or Console()
    out = release_dir(cfg)
    items, skipped = gather_runs(cfg)
    rows = []
    for item in items:
        try:  # a state that does not load is set aside here; verify checks the rest
            dim = int(np.load(item.scene_state, allow_pickle=False).shape[0])
        except (OSError, ValueError, EOFError, IndexError) as e:
            skipped.append(QuarantineEntry(key=item.annotation.key, stage="release", source="stage2",
                                           reason=QuarantineReason.unreadable_state, detail=f"{item.scene_state}: {e}"))
            continue
        bddl, state, history = _place_files(item, out)
        rows.append(_row(item, out, bddl, state, history, dim))

    refs = scene_refs(rows, out)
    certs = certify_all(refs, cfg, out / BUILD_DIR / "certificates", cfg.release.certify_expert,
                        executor=executor, console=console)
    for i, ref in enumerate(refs):
        c = certs.get(ref.unit)
        if c is not None:
            rows[i] = rows[i].model_copy(update={"certified": c.certified, "certify_tries": c.tries,
                                                 "certify_successes": c.successes,
                                                 "certify_reason": c.reason})

    positions = collect(refs, cfg, out / BUILD_DIR / "positions", executor=executor, console=console)
    for p in positions:
        if p["note"]:
            console.print(f"[yellow]object positions[/yellow] {p['note']}", highlight=False)

    rows, split = apply_split(rows, cfg.release.split)
    write_manifest(out / MANIFEST_NAME, rows)
    write_json(ReleaseLayout(out).split, split.model_dump(mode="json"))
    write_figure(rows, out / FIGURE)
    write_positions_figure(positions, out / POSITIONS_FIGURE)
    hashes = {
        "localization": sorted({r.localize_prompt_hash for r in rows if r.localize_prompt_hash}),
        "characterization": sorted({r.characterize_prompt_hash for r in rows if r.characterize_prompt_hash}),
    }
    people = {r.reviewer for it in items for r in it.annotation.reviews}
    write_text(ReleaseLayout(out).card, render_card(rows, cfg, hashes, len(people)))

    released = sorted({p for r in rows for p, _ in r.files()}
                      | {MANIFEST_NAME, FIGURE, POSITIONS_FIGURE, RELEASE_CARD, RELEASE_SPLIT})
    removed = _remove_stale(out, set(released))
    write_text(out / SUMS_NAME, "".join(f"{sha256_file(out / p)}  {p}\n" for p in released))

    # outside the checksummed set: when it was built and what was left out, with reasons
    write_json(out / BUILD_DIR / "build_info.json", {
        "built_at": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "scenes": len(rows), "skipped": len(skipped), "stale_files_removed": removed,
    })
    write_text(ReleaseLayout(out).quarantine_log, "".join(q.model_dump_json() + "\n" for q in skipped))
    colour = "green" if rows else "yellow"
    console.print(f"[{colour}]released {len(rows)} scene(s)[/{colour}] to {out}"
                  + (f"; [yellow]{len(skipped)} annotation(s) set aside[/yellow] (see {ReleaseLayout(out).quarantine_log})"
                     if skipped else ""))
    for q in skipped:
        console.print(f"  [yellow]{q.reason}[/yellow] {q.key}: {q.detail}", highlight=False)
    return rows


def run(cfg: Config) -> None:
    from pipeline.config import save_resolved

    out = release_dir(cfg)
    build(cfg)
    save_resolved(cfg, out / BUILD_DIR)
