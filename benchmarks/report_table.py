"""The tuning protocol's table (README, "Tuning protocol"): runs side by side, one column each.

For each run folder (stages 1-3 reviewed and released, and `recover bench-localize` run on it):
episodes and failure rate overall and per suite (stage 1's manifest); released scenes and the
recovery expert's certificates overall, per level and per suite (the release's
`scenarios.parquet`); the `simstate` localizer and characterizer against the generator's
truth (onset within ±0.5 s and ±1 s, category, level: `<run>/bench/localize_simstate/report.json`).
The aims of issue 26 (certified >= 90% overall and >= 80% in every level with >= 5 scenes;
onset ±1 s, category and level >= 90%) are marked. Then, per run, the cases to look at: every
uncertified scene with its reason, and every episode the localizer missed by more than 1 s or
labelled with another category or level than the truth.

    .venv/bin/python benchmarks/report_table.py RUN [RUN ...] [--names a b] [--out STEM]

Writes STEM.md and STEM.json (default benchmarks/results/report_table).
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import pyarrow.parquet as pq
from failure_mix import side_by_side  # benchmarks/ is the script's own folder
from rich.console import Console

from pipeline.layout import RunLayout
from pipeline.records import read_episodes

REPO = Path(__file__).resolve().parents[1]
AIM_CERT, AIM_CERT_LEVEL, AIM_LEVEL_MIN_SCENES, AIM_LOCALIZE = 0.90, 0.80, 5, 0.90
LEVELS = ("L1", "L2", "L3", "L4")


def figures(run: Path) -> dict:
    layout = RunLayout(run)
    episodes = read_episodes(layout.stage1.manifest)
    suites = sorted({e.suite for e in episodes})
    out: dict = {"episodes": len(episodes), "failed": sum(not e.success for e in episodes),
                 "failed_by_suite": {s: [sum(not e.success for e in episodes if e.suite == s),
                                         sum(e.suite == s for e in episodes)] for s in suites}}
    manifest = run / "release" / "scenarios.parquet"
    scenes = pq.read_table(manifest).to_pylist() if manifest.is_file() else []  # not released: no scenes
    out["scenes"] = len(scenes)
    out["certified"] = sum(bool(r["certified"]) for r in scenes)
    for dim, key in (("level", "level"), ("suite", "suite")):
        n, c = Counter(r[key] for r in scenes), Counter(r[key] for r in scenes if r["certified"])
        out[f"certified_by_{dim}"] = {v: [c[v], n[v]] for v in sorted(n)}
    out["uncertified"] = [{"scene": f"{r['suite']}/{r['task']}/{r['episode_id']}@{r['step']}", "level": r["level"],
                           "category": r["category"], "reason": r["certify_reason"]}
                          for r in scenes if not r["certified"]]
    rep = json.loads((layout.bench("simstate") / "report.json").read_text())
    out["localize"] = {k: rep[k] for k in ("truths", "localized", "set_aside", "within_0_5s", "within_1s",
                                           "category_accuracy", "level_accuracy")}
    out["mislocalized"] = [
        {"episode": e["key"], "truth": f"{e['truth_time_s']:.2f} s {e['truth_category']} {e['truth_level']}",
         "predicted": ("-" if e["pred_step"] is None else f"{e['error_s']:+.2f} s") +
         f" {e['pred_category']} {e['pred_level']}", "reason": e.get("reason") or ""}
        for e in rep["episodes"]
        if e["pred_step"] is None or abs(e["error_s"]) > 1.0 or e["pred_category"] != e["truth_category"]
        or e["pred_level"] != e["truth_level"]]
    return out


def pct(k: int, n: int) -> str:
    return f"{k}/{n} ({k / n:.0%})" if n else "-"


def share(v: float | None) -> str:
    return "-" if v is None else f"{v:.0%}"


def rows(figs: list[dict]) -> list[tuple[str, list[str]]]:
    out = [("episodes, failed", [pct(f["failed"], f["episodes"]) for f in figs])]
    for s in sorted({s for f in figs for s in f["failed_by_suite"]}):
        out.append((f"failed: {s}", [pct(*f["failed_by_suite"].get(s, [0, 0])) for f in figs]))
    out.append((f"released scenes, certified (aim {AIM_CERT:.0%})", [pct(f["certified"], f["scenes"]) for f in figs]))
    for lv in LEVELS:
        out.append((f"certified: {lv} (aim {AIM_CERT_LEVEL:.0%} if >= {AIM_LEVEL_MIN_SCENES})",
                    [pct(*f["certified_by_level"].get(lv, [0, 0])) for f in figs]))
    for s in sorted({s for f in figs for s in f["certified_by_suite"]}):
        out.append((f"certified: {s}", [pct(*f["certified_by_suite"].get(s, [0, 0])) for f in figs]))
    out.append(("localized / with truth (set aside)",
                [f"{f['localize']['localized']}/{f['localize']['truths']} ({f['localize']['set_aside']})" for f in figs]))
    for key, name in (("within_0_5s", "onset within ±0.5 s"), ("within_1s", f"onset within ±1 s (aim {AIM_LOCALIZE:.0%})"),
                      ("category_accuracy", f"category (aim {AIM_LOCALIZE:.0%})"),
                      ("level_accuracy", f"level (aim {AIM_LOCALIZE:.0%})")):
        out.append((name, [share(f["localize"][key]) for f in figs]))
    return out


def aims_met(f: dict) -> dict[str, bool]:
    lv = f["certified_by_level"]
    loc = f["localize"]
    released = {"certified": f["scenes"] > 0 and f["certified"] / f["scenes"] >= AIM_CERT,
                "certified per level": all(c / n >= AIM_CERT_LEVEL for c, n in lv.values() if n >= AIM_LEVEL_MIN_SCENES)}
    return {**(released if f["scenes"] else {}),
            **{k: (loc[k] or 0) >= AIM_LOCALIZE for k in ("within_1s", "category_accuracy", "level_accuracy")}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--names", nargs="+", default=None)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "report_table")
    a = ap.parse_args()
    names = a.names or [r.name for r in a.runs]
    if len(names) != len(a.runs):
        ap.error("--names needs one name per run")
    figs = [figures(r) for r in a.runs]
    console = Console()
    md = side_by_side("tuning protocol: certificates and simstate labels against the truth", names, rows(figs))
    for name, f in zip(names, figs, strict=True):
        met = aims_met(f)
        line = f"{name}: aims " + ", ".join(f"{k} {'met' if v else 'MISSED'}" for k, v in met.items())
        console.print(line)
        md += ["", f"### {name}", "", line, "", "Not certified:", ""]
        md += [f"- `{u['scene']}` ({u['level']}, {u['category']}): {u['reason']}" for u in f["uncertified"]] or ["- none"]
        md += ["", "Localized off by > 1 s, or another category or level than the truth:", ""]
        md += [f"- `{m['episode']}`: truth {m['truth']}; simstate {m['predicted']} {m['reason']}".rstrip()
               for m in f["mislocalized"]] or ["- none"]
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".md").write_text("\n".join(md) + "\n")
    a.out.with_suffix(".json").write_text(json.dumps(dict(zip(names, figs, strict=True)), indent=2))
    console.print(f"wrote {a.out.with_suffix('.md')} and .json")


if __name__ == "__main__":
    main()
