"""`recover bench-localize`: score a localizer (and its characterizer) against the truth
the scripted generator recorded, on a run folder.

Inputs: `<run>/stage1/episodes.parquet` and, per failed episode, `truth.parquet` (see
`pipeline.truth.derive`); for `simstate` the stage-2 evidence file when there is one (else
the evidence is computed from the logged states on the simulator, nothing is written to
stage2/); for `openai` / `transformers` the episode's agentview video and frame table.
Failed episodes without a usable truth are set aside with their reason and counted.

Localizers:
Every localizer and characterizer is the one stages 2 and 3 use, built by
`pipeline.labelers.registry` and called through the `Localizer` / `Characterizer` protocols:
- simstate: the simstate localizer on the evidence for the onset, then the simstate
  characterizer for level and category (current rules and thresholds).
- openai | transformers: `stage2.vlm` with the chosen backend; one model is asked to localize,
  then to characterize at its own onset; answers go through the project's parser. An
  unusable answer is a miss, with its quarantine reason.

Output, under `<run>/bench/localize_<localizer>/` (or `--out`), written atomically:
    report.json        every figure below, the per-episode rows and the set-aside reasons
    report.md          the same as tables, for the README and notes
    confusion_level.png, confusion_category.png   (when matplotlib is installed)
Figures: onset mean absolute error (s), share within +-0.5 s and +-1 s (of all scored
truths: an episode the localizer found nothing in is a miss), onset before / at / after
the truth, level and category accuracy (of those with a prediction), confusion matrices
(truth rows, prediction columns, "none" for no prediction), and the worst cases with
their episode keys.
"""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

from pipeline.atomic import write_json, write_text, write_with
from pipeline.config import Config
from pipeline.errors import FatalError
from pipeline.labelers.base import Characterizer, Episode
from pipeline.labelers.registry import make_characterizer, make_localizer
from pipeline.layout import REPORT, RunLayout, Stage1Layout
from pipeline.records import Category, Characterization, EpisodeRecord, Level, Localization, Phases, read_episodes
from pipeline.truth.derive import EpisodeTruth, TruthError, episode_truth

LOCALIZERS = ("simstate", "openai", "transformers")
WORST = 10


@dataclass
class Prediction:
    key: str
    fail_step: int | None = None
    level: str | None = None
    category: str | None = None
    reason: str = ""  # why a value is missing (no_failure_found, a quarantine reason, ...)


def load_truths(run_dir: Path) -> tuple[list[EpisodeRecord], dict[str, EpisodeTruth], dict[str, str]]:
    """Failed episodes, their truths, and key -> reason for those set aside."""
    stage1 = RunLayout(run_dir).stage1
    manifest = stage1.manifest
    if not manifest.is_file():
        raise FatalError(f"{manifest}: no stage 1 manifest; run `recover stage1` first")
    failed = [r for r in read_episodes(manifest) if not r.success]
    truths, aside = {}, {}
    for rec in failed:
        try:
            truths[rec.key] = episode_truth(stage1.episode(rec).truth, rec.key, rec.control_hz)
        except TruthError as e:
            aside[rec.key] = f"{e.reason}: {e}"
    return failed, truths, aside


# ---- localizers --------------------------------------------------------------------------
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
                       events=()) -> Localization:
    """A Localization at the localizer's own onset (no scene is written: only the characterizer reads it)."""
    phases = phases or Phases(pre=(0, step), during=(step, min(step + 1, rec.steps + 1)),
                              post=(min(step + 1, rec.steps + 1), rec.steps + 1))
    return Localization(key=rec.key, suite=rec.suite, task=rec.task, episode_id=rec.episode_id,
                        instruction=rec.instruction, source=source, fail_step=step, fail_time_s=time_s,
                        phases=phases, scene_bddl="", scene_state="", events=list(events))


def _characterize(characterizer: Characterizer, out: dict[str, Prediction], locs: list[Localization]) -> None:
    for loc, got in zip(locs, characterizer.characterize(locs), strict=True):
        if isinstance(got, Characterization):
            out[loc.key].level, out[loc.key].category = got.recovery_level.value, got.failure_category.value
        else:
            out[loc.key].reason = f"characterize: {got.reason}"


def predict_simstate(cfg: Config, records: list[EpisodeRecord]) -> dict[str, Prediction]:
    from pipeline.evidence import compute_evidence, read_evidence
    from pipeline.stage2.layout import load_episode
    from pipeline.stage2.phases import split_phases

    layout = RunLayout.of(cfg)
    run_dir, paths = layout.root, layout.stage2
    vlm_cfg = cfg.stage2.vlm.model_copy(update={"backend": "simstate"})
    localizer = make_localizer(vlm_cfg)
    evidence: dict[str, object] = {}
    characterizer = make_characterizer(vlm_cfg, run_dir, evidence_for=lambda loc: evidence[loc.key])
    out: dict[str, Prediction] = {}
    by_task: dict[tuple[str, str], list[EpisodeRecord]] = defaultdict(list)
    for rec in records:
        by_task[(rec.suite, rec.task)].append(rec)
    for (suite, task), recs in sorted(by_task.items()):
        env = None
        for rec in recs:
            stored = paths.abs(paths.evidence(rec))
            try:
                if stored.is_file():
                    ev = read_evidence(stored)
                else:  # no stage 2 yet: measure the logged states (nothing is written)
                    if env is None:
                        from pipeline.sim import build_env, get_task

                        env = build_env(get_task(suite, task))
                    ep = load_episode(layout.stage1.root, rec)
                    ev = compute_evidence(env, ep.states, ep.steps["action"][:, 6], rec.control_hz)
            except Exception as e:  # noqa: BLE001 - one bad episode is a miss, the rest go on
                out[rec.key] = Prediction(rec.key, reason=f"evidence: {type(e).__name__}: {e}")
                continue
            [onset] = localizer.localize([_episode(layout.stage1.root, rec, ev)])
            if onset.fail_step is None:
                out[rec.key] = Prediction(rec.key, reason=onset.reason or "no_failure_found")
                continue
            step = min(onset.fail_step, len(ev) - 1)
            loc = _stub_localization(rec, step, step / rec.control_hz, localizer.name,
                                     split_phases(ev, step, cfg.stage2.settle_speed_mps, cfg.stage2.settle_steps),
                                     onset.events)
            out[rec.key] = Prediction(rec.key, step)
            evidence[rec.key] = ev
            _characterize(characterizer, out, [loc])
            del evidence[rec.key]
        if env is not None:
            env.close()
    return out


def predict_vlm(cfg: Config, backend_name: str, records: list[EpisodeRecord]) -> dict[str, Prediction]:
    from pipeline.stage2.phases import step_for_time

    stage1 = RunLayout.of(cfg).stage1.root
    out: dict[str, Prediction] = {}
    episodes = [_episode(stage1, rec) for rec in records]
    if not any(e.video is not None for e in episodes):
        return {e.record.key: Prediction(e.record.key, reason="no_video") for e in episodes}
    vlm_cfg = cfg.stage2.vlm.model_copy(update={"backend": backend_name})
    localizer = make_localizer(vlm_cfg)
    try:  # one model answers both questions
        characterizer = make_characterizer(vlm_cfg, Path(cfg.out), backend=localizer.backend)
        located = []
        for ep, onset in zip(episodes, localizer.localize(episodes), strict=True):
            rec = ep.record
            if not onset.found:
                out[rec.key] = Prediction(rec.key, reason=onset.reason or "backend_error")
                continue
            step = step_for_time(onset.fail_time_s, ep.frames, rec.steps, rec.control_hz)
            out[rec.key] = Prediction(rec.key, step)
            located.append(_stub_localization(rec, step, onset.fail_time_s, localizer.name))
        if located:
            _characterize(characterizer, out, located)
    finally:
        localizer.close()
    return out


# ---- scoring -----------------------------------------------------------------------------
def _confusion(pairs: list[tuple[str, str | None]], labels: list[str]) -> dict[str, dict[str, int]]:
    m = {t: {p: 0 for p in [*labels, "none"]} for t in labels}
    for t, p in pairs:
        m.setdefault(t, {q: 0 for q in [*labels, "none"]})[p or "none"] += 1
    return m


def score(truths: dict[str, EpisodeTruth], preds: dict[str, Prediction], control_hz: int = 20) -> dict:
    """Every figure of the benchmark (see the module docstring) over the truths' keys."""
    rows = []
    for key, t in sorted(truths.items()):
        p = preds.get(key) or Prediction(key, reason="not_run")
        err = None if p.fail_step is None else (p.fail_step - t.onset_step) / control_hz
        rows.append({"key": key, "truth_step": t.onset_step, "truth_time_s": t.onset_time_s,
                     "truth_outcome": t.outcome, "truth_category": t.category, "truth_level": t.level,
                     "pred_step": p.fail_step, "pred_category": p.category, "pred_level": p.level,
                     "error_s": err, "reason": p.reason})
    n = len(rows)
    errs = [r["error_s"] for r in rows if r["error_s"] is not None]
    abs_errs = sorted(abs(e) for e in errs)
    with_ch = [r for r in rows if r["pred_level"] is not None]
    share = (lambda k: round(k / n, 4) if n else None)
    report = {
        "truths": n, "localized": len(errs), "unlocalized": n - len(errs),
        "unlocalized_reasons": dict(Counter(r["reason"] or "?" for r in rows if r["error_s"] is None)),
        "onset_mae_s": round(sum(abs_errs) / len(abs_errs), 3) if abs_errs else None,
        "onset_median_abs_s": round(abs_errs[len(abs_errs) // 2], 3) if abs_errs else None,
        "within_0_5s": share(sum(a <= 0.5 + 1e-9 for a in abs_errs)),
        "within_1s": share(sum(a <= 1.0 + 1e-9 for a in abs_errs)),
        "before_truth": sum(e < 0 for e in errs), "at_truth": sum(e == 0 for e in errs),
        "after_truth": sum(e > 0 for e in errs),
        "characterized": len(with_ch),
        "level_accuracy": round(sum(r["pred_level"] == r["truth_level"] for r in with_ch) / len(with_ch), 4)
        if with_ch else None,
        "category_accuracy": round(sum(r["pred_category"] == r["truth_category"] for r in with_ch) / len(with_ch), 4)
        if with_ch else None,
        "level_confusion": _confusion([(r["truth_level"], r["pred_level"]) for r in rows], [lv.value for lv in Level]),
        "category_confusion": _confusion([(r["truth_category"], r["pred_category"]) for r in rows],
                                         [c.value for c in Category]),
        "truth_outcomes": dict(Counter(r["truth_outcome"] for r in rows)),
        "worst": sorted(rows, key=lambda r: -(abs(r["error_s"]) if r["error_s"] is not None else float("inf")))[:WORST],
        "episodes": rows,
    }
    return report


# ---- output ------------------------------------------------------------------------------
def _md_matrix(title: str, m: dict[str, dict[str, int]]) -> list[str]:
    cols = list(next(iter(m.values())).keys()) if m else []
    lines = [f"### {title} (rows: truth, columns: prediction)", "", "| truth \\ pred | " + " | ".join(cols) + " |",
             "|---" * (len(cols) + 1) + "|"]
    lines += [f"| {t} | " + " | ".join(str(v) for v in row.values()) + " |" for t, row in m.items()]
    return lines + [""]


def markdown(report: dict, localizer: str, run_dir: Path) -> str:
    pct = (lambda v: "-" if v is None else f"{v:.0%}")
    lines = [f"# bench-localize: {localizer} on {run_dir}", "",
             f"Failed episodes: {report['failed']}, with truth: {report['truths']} "
             f"(set aside: {report['set_aside_reasons'] or 'none'}).", "",
             "| figure | value |", "|---|---|",
             f"| localized | {report['localized']} of {report['truths']} "
             f"(misses: {report['unlocalized_reasons'] or '-'}) |",
             f"| onset MAE | {report['onset_mae_s']} s (median {report['onset_median_abs_s']} s) |",
             f"| within ±0.5 s / ±1 s | {pct(report['within_0_5s'])} / {pct(report['within_1s'])} |",
             f"| before / at / after truth | {report['before_truth']} / {report['at_truth']} / "
             f"{report['after_truth']} |",
             f"| level accuracy | {pct(report['level_accuracy'])} (of {report['characterized']}) |",
             f"| category accuracy | {pct(report['category_accuracy'])} (of {report['characterized']}) |",
             f"| truth outcomes | {report['truth_outcomes']} |", ""]
    lines += _md_matrix("Level", report["level_confusion"]) + _md_matrix("Category", report["category_confusion"])
    lines += ["### Worst cases", "", "| episode | truth | predicted | error | truth outcome / category / level | "
              "predicted category / level |", "|---|---|---|---|---|---|"]
    for r in report["worst"]:
        err = "none: " + (r["reason"] or "?") if r["error_s"] is None else f"{r['error_s']:+.2f} s"
        pred = "-" if r["pred_step"] is None else f"{r['pred_step'] / report['control_hz']:.2f} s"
        lines.append(f"| {r['key']} | {r['truth_time_s']:.2f} s | {pred} | {err} | {r['truth_outcome']} / "
                     f"{r['truth_category']} / {r['truth_level']} | {r['pred_category']} / {r['pred_level']} |")
    return "\n".join(lines) + "\n"


def plot_confusion(path: Path, title: str, m: dict[str, dict[str, int]]) -> bool:
    """A confusion-matrix PNG; False when matplotlib is not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    rows = list(m)
    cols = list(next(iter(m.values())).keys()) if m else []
    data = [[m[r][c] for c in cols] for r in rows]
    fig, ax = plt.subplots(figsize=(1.2 + 0.9 * len(cols), 1.0 + 0.6 * len(rows)))
    ax.imshow(data, cmap="Blues")
    ax.set_xticks(range(len(cols)), [c.replace("_", "\n") for c in cols], fontsize=7)
    ax.set_yticks(range(len(rows)), [r.replace("_", " ") for r in rows], fontsize=7)
    ax.set_xlabel("predicted")
    ax.set_ylabel("truth")
    ax.set_title(title, fontsize=9)
    for i, row in enumerate(data):
        for j, v in enumerate(row):
            ax.text(j, i, str(v), ha="center", va="center", fontsize=8)
    fig.tight_layout()
    write_with(path, lambda p: fig.savefig(p, dpi=110))
    plt.close(fig)
    return True


def run(cfg: Config, localizer: str = "simstate", out: Path | None = None) -> dict:
    if localizer not in LOCALIZERS:
        raise FatalError(f"--localizer {localizer!r}: choose one of {LOCALIZERS}")
    run_dir = Path(cfg.out)
    failed, truths, aside = load_truths(run_dir)
    scored = [r for r in failed if r.key in truths]
    if localizer == "simstate":
        preds = predict_simstate(cfg, scored)
    else:
        preds = predict_vlm(cfg, localizer, scored)
    hz = failed[0].control_hz if failed else 20
    report = {"localizer": localizer, "run": str(run_dir), "control_hz": hz, "failed": len(failed),
              "set_aside": len(aside), "set_aside_reasons": dict(Counter(v.split(":")[0] for v in aside.values())),
              **score(truths, preds, hz), "set_aside_episodes": aside,
              "truth": {k: t.model_dump(mode="json") for k, t in truths.items()}}
    folder = out or RunLayout(run_dir).bench(localizer)
    write_json(folder / "report.json", report)
    write_text(folder / REPORT, markdown(report, localizer, run_dir))
    report["plots"] = [str(folder / f"confusion_{k}.png") for k in ("level", "category")
                       if plot_confusion(folder / f"confusion_{k}.png", f"{localizer}: {k}", report[f"{k}_confusion"])]
    return report


def summary_lines(report: dict) -> list[str]:
    pct = (lambda v: "-" if v is None else f"{v:.0%}")
    return [f"{report['localizer']}: {report['truths']} failed episodes with truth "
            f"({report['set_aside']} set aside), localized {report['localized']}",
            f"onset MAE {report['onset_mae_s']} s, within ±0.5 s {pct(report['within_0_5s'])}, "
            f"±1 s {pct(report['within_1s'])}, before/at/after {report['before_truth']}/{report['at_truth']}/"
            f"{report['after_truth']}",
            f"level accuracy {pct(report['level_accuracy'])}, category accuracy {pct(report['category_accuracy'])}"]
