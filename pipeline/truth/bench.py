"""`recover bench-localize`: score a localizer (and its characterizer) against the truth
the scripted generator recorded, on a run folder.

Inputs: `<run>/stage1/episodes.parquet` and, per failed episode, `truth.parquet` (see
`pipeline.truth.derive`); for `simstate` the stage-2 evidence file when there is one (else
the evidence is computed from the logged states on the simulator, nothing is written to
stage2/); for `openai` / `transformers` the episode's agentview video and frame table.
Failed episodes without a usable truth are set aside with their reason and counted.

Localizers: `simstate`, or `openai` | `transformers` (`stage2.vlm` with the chosen backend):
the ones stages 2 and 3 use, run on each scored episode as a Stage on the configured
executor (`pipeline.truth.predict`: `BenchStage`, whose done markers keep each episode's
prediction, so a rerun with the same inputs, config and labeler code asks nothing again).

Output, under `<run>/bench/localize_<localizer>/` (or `--out`), written atomically:
    report.json        every figure below, the per-episode rows and the set-aside reasons
    report.md          the same as tables, for the README and notes
    confusion_level.png, confusion_category.png   (when matplotlib is installed)
    _done/<suite>__<task>__<episode_id>.done     each episode's prediction (the runner's marker)
Figures: onset mean absolute error (s), share within +-0.5 s and +-1 s (of all scored
truths: an episode the localizer found nothing in is a miss), onset before / at / after
the truth, level and category accuracy (of those with a prediction), confusion matrices
(truth rows, prediction columns, "none" for no prediction), and the worst cases with
their episode keys.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from rich.console import Console

from pipeline.atomic import write_json, write_text, write_with
from pipeline.config import Config
from pipeline.errors import FatalError
from pipeline.layout import REPORT, RunLayout
from pipeline.records import Category, EpisodeRecord, Level, read_episodes
from pipeline.runner import Event
from pipeline.truth.derive import SETTLE, EpisodeTruth, TruthError, episode_truth, settle_of
from pipeline.truth.predict import BenchStage, Prediction

LOCALIZERS = ("simstate", "openai", "transformers")
WORST = 10


def load_truths(run_dir: Path, settle: tuple[float, int] = SETTLE
                ) -> tuple[list[EpisodeRecord], dict[str, EpisodeTruth], dict[str, str]]:
    """Failed episodes, their truths, and key -> reason for those set aside. A truth's level
    reaches the settled scene where stage 2's evidence file is there (`derive`; `settle`:
    stage 2's speed and calm steps)."""
    layout = RunLayout(run_dir)
    stage1 = layout.stage1
    manifest = stage1.manifest
    if not manifest.is_file():
        raise FatalError(f"{manifest}: no stage 1 manifest; run `recover stage1` first")
    failed = [r for r in read_episodes(manifest) if not r.success]
    truths, aside = {}, {}
    for rec in failed:
        try:
            truths[rec.key] = episode_truth(stage1.episode(rec).truth, rec.key, rec.control_hz,
                                            layout.stage2.abs(layout.stage2.evidence(rec)), settle)
        except TruthError as e:
            aside[rec.key] = f"{e.reason}: {e}"
    return failed, truths, aside


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
             f"(set aside: {report['set_aside_reasons'] or 'none'}); the truth's level read to: "
             f"{report.get('truth_level_windows') or '-'} (scene: the settled state, attempt: the generator's "
             "attempt end).", "",
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


def predict(cfg: Config, localizer: str, records: list[EpisodeRecord], folder: Path,
            console: Console | None = None) -> dict[str, Prediction]:
    """Every episode's Prediction, by key, after running the missing ones on the configured
    executor; an episode set aside is a miss whose reason says why."""
    from pipeline.executors import make_executor
    from pipeline.runner import Runner

    stage = BenchStage(cfg, localizer, records, folder)
    aside: dict[str, Event] = {}
    Runner(make_executor(cfg.executor), console=console).run(
        stage, cfg, on_event=lambda ev: aside.__setitem__(ev.unit, ev) if ev.kind == "set_aside" else None)
    preds = stage.predictions()
    for rec in records:
        if (ev := aside.get(stage.unit_id(rec))) is not None and rec.key not in preds:
            preds[rec.key] = Prediction(rec.key, reason=f"set aside: {ev.reason}: {ev.detail}")
    return preds


def run(cfg: Config, localizer: str = "simstate", out: Path | None = None) -> dict:
    if localizer not in LOCALIZERS:
        raise FatalError(f"--localizer {localizer!r}: choose one of {LOCALIZERS}")
    run_dir = Path(cfg.out)
    failed, truths, aside = load_truths(run_dir, settle_of(cfg.stage2))
    scored = [r for r in failed if r.key in truths]
    folder = out or RunLayout(run_dir).bench(localizer)
    preds = predict(cfg, localizer, scored, folder)
    hz = failed[0].control_hz if failed else 20
    report = {"localizer": localizer, "run": str(run_dir), "control_hz": hz, "failed": len(failed),
              "set_aside": len(aside), "set_aside_reasons": dict(Counter(v.split(":")[0] for v in aside.values())),
              "truth_level_windows": dict(Counter(t.level_window for t in truths.values())),
              **score(truths, preds, hz), "set_aside_episodes": aside,
              "truth": {k: t.model_dump(mode="json") for k, t in truths.items()}}
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
