"""`recover bench-localize`: score a localizer (and its characterizer) against the truth
the scripted generator recorded, on a run folder.

Inputs: `<run>/stage1/episodes.parquet` and, per failed episode, `truth.parquet` (see
`pipeline.truth.derive`); for `simstate` the stage-2 evidence file when there is one (else
the evidence is computed from the logged states on the simulator, nothing is written to
stage2/); for `openai` / `transformers` the episode's agentview video and frame table.
Failed episodes without a usable truth are set aside with their reason and counted.

Localizers:
- simstate: `pipeline.labelers.simstate.localizer.localize` for the onset, then
  `pipeline.labelers.simstate.characterizer.characterize` for level and category (the same calls
  stages 2 and 3 make, with the current rules and thresholds).
- openai | transformers: the VLM backend of `stage2.vlm` (backend replaced by the chosen
  one) asked to localize, then to characterize at its own onset; answers go through the
  project's parser. An unusable answer is a miss, with its quarantine reason.

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
from pipeline.records import Category, EpisodeRecord, Level, read_episodes
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
    manifest = run_dir / "stage1" / "episodes.parquet"
    if not manifest.is_file():
        raise FatalError(f"{manifest}: no stage 1 manifest; run `recover stage1` first")
    failed = [r for r in read_episodes(manifest) if not r.success]
    truths, aside = {}, {}
    for rec in failed:
        try:
            truths[rec.key] = episode_truth(run_dir / "stage1" / rec.path / "truth.parquet", rec.key, rec.control_hz)
        except TruthError as e:
            aside[rec.key] = f"{e.reason}: {e}"
    return failed, truths, aside


# ---- localizers --------------------------------------------------------------------------
def predict_simstate(cfg: Config, records: list[EpisodeRecord]) -> dict[str, Prediction]:
    from pipeline.labelers.simstate.characterizer import characterize
    from pipeline.evidence import compute_evidence, read_evidence
    from pipeline.records import Localization
    from pipeline.stage2.layout import Stage2Paths, load_episode
    from pipeline.stage2.phases import split_phases
    from pipeline.labelers.simstate.localizer import localize

    run_dir, paths = Path(cfg.out), Stage2Paths(Path(cfg.out) / "stage2")
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
                    ep = load_episode(run_dir / "stage1", rec)
                    ev = compute_evidence(env, ep.states, ep.steps["action"][:, 6], rec.control_hz)
            except Exception as e:  # noqa: BLE001 - one bad episode is a miss, the rest go on
                out[rec.key] = Prediction(rec.key, reason=f"evidence: {type(e).__name__}: {e}")
                continue
            sim = localize(ev)
            if sim.onset_step is None:
                out[rec.key] = Prediction(rec.key, reason="no_failure_found")
                continue
            onset = min(sim.onset_step, len(ev) - 1)
            loc = Localization(
                key=rec.key, suite=rec.suite, task=rec.task, episode_id=rec.episode_id, instruction=rec.instruction,
                source="simstate", fail_step=onset, fail_time_s=onset / rec.control_hz,
                phases=split_phases(ev, onset, cfg.stage2.settle_speed_mps, cfg.stage2.settle_steps),
                scene_bddl="", scene_state="", events=sim.events)
            ch = characterize(loc, ev)
            out[rec.key] = Prediction(rec.key, onset, ch.recovery_level.value, ch.failure_category.value)
        if env is not None:
            env.close()
    return out


def predict_vlm(cfg: Config, backend_name: str, records: list[EpisodeRecord]) -> dict[str, Prediction]:
    import pyarrow.parquet as pq

    from pipeline.stage2.phases import step_for_time
    from pipeline.stage2.vlm_step import _stored
    from pipeline.labelers.vlm.backends import VLMRequest, make_backend
    from pipeline.labelers.vlm.parse import parse_characterization
    from pipeline.labelers.vlm.schemas import Quarantine

    stage1 = Path(cfg.out) / "stage1"
    out: dict[str, Prediction] = {}
    asked, frames = [], {}
    for rec in records:
        video = rec.videos.get("agentview")
        folder = stage1 / rec.path
        if not video or not (folder / video).is_file():
            out[rec.key] = Prediction(rec.key, reason="no_video")
            continue
        fp = folder / "frames.parquet"
        frames[rec.key] = pq.read_table(fp) if fp.is_file() else None
        asked.append(rec)
    if not asked:
        return out
    backend = make_backend(cfg.stage2.vlm.model_copy(update={"backend": backend_name}))
    try:
        reqs = [VLMRequest(task="localize", video=stage1 / r.path / r.videos["agentview"], instruction=r.instruction,
                           frames_table=frames[r.key], key=r.key) for r in asked]
        located = []
        for rec, res in zip(asked, backend.run(reqs), strict=True):
            got = _stored(res, rec, frames[rec.key])
            if "fail_time_s" not in got:
                out[rec.key] = Prediction(rec.key, reason=got.get("reason", "backend_error"))
                continue
            step = step_for_time(float(got["fail_time_s"]), frames[rec.key], rec.steps, rec.control_hz)
            out[rec.key] = Prediction(rec.key, step)
            located.append((rec, float(got["fail_time_s"])))
        reqs = [VLMRequest(task="characterize", video=stage1 / r.path / r.videos["agentview"],
                           instruction=r.instruction, fail_time_s=t, frames_table=frames[r.key], key=r.key)
                for r, t in located]
        for (rec, _), res in zip(located, backend.run(reqs) if reqs else [], strict=True):
            ans = parse_characterization(res)
            if isinstance(ans, Quarantine):
                out[rec.key].reason = f"characterize: {ans.reason.value}"
            else:
                out[rec.key].level, out[rec.key].category = ans.recovery_level.value, ans.failure_category.value
    finally:
        backend.close()
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
    folder = out or run_dir / "bench" / f"localize_{localizer}"
    write_json(folder / "report.json", report)
    write_text(folder / "report.md", markdown(report, localizer, run_dir))
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
