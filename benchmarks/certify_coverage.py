"""Certified share of a release's scenes: the plain expert vs the recovery expert, side by side.

Takes a run folder (its `release/scenarios.parquet`) or a release folder, and certifies
every released scene twice in one run, as `recover release` does
(`pipeline.release.certify.certify_one`: up to `--tries` tries, horizon `--horizon`,
chunk `--chunk`): once with the plain scripted expert at zero noise (before) and once
with the recovery expert (after). Work units are (scene BDDL group, expert); a process
pool builds one environment per unit. Prints a rich table of the certified share overall
and per level, suite and category, with the recovery expert's reasons for the scenes it
did not certify; writes it as markdown, the per-scene rows as JSON and a bar chart PNG to
benchmarks/results/ (`--out` stem).

    .venv/bin/python benchmarks/certify_coverage.py runs/default [--tries 2] [--horizon 520] \\
        [--workers 2] [--out benchmarks/results/certify_coverage]

`--stage2` certifies the scenes stage 2 chose instead (`stage2/localizations.parquet`, no
review or release needed: a tuning run's scenes), with the level and category stage 3 gave
each (`unknown` before stage 3).
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from rich.console import Console
from rich.progress import Progress
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "certify_coverage"
EXPERTS = ("plain", "recovery")
AIM_ALL, AIM_LEVEL = 0.90, 0.80  # issue 26's aims for the recovery expert (a level: with >= 5 scenes)


def certify_unit(release: str, scenes: list[dict], expert: str, tries: int, horizon: int, chunk: int) -> list[dict]:
    """Certify the scenes of one BDDL group with one expert, in one environment."""
    import numpy as np

    from pipeline.config import Config
    from pipeline.release.certify import certify_one
    from pipeline.release.experts import expert_factory
    from pipeline.release.scene_physics import scene_task
    from pipeline.sim import SimEnv

    root = Path(release)
    first = scenes[0]
    factory = expert_factory(expert, Config())
    rows = []
    with SimEnv(scene_task(first["suite"], first["task"], first["instruction"], root / first["bddl_path"])) as env:
        for s in scenes:
            t0 = time.perf_counter()
            cert = certify_one(env, np.load(root / s["state_path"]), factory, tries, horizon, chunk)
            rows.append({"scene": s["scene"], "suite": s["suite"], "level": s["level"], "category": s["category"],
                         "expert": expert, "certified": cert.certified, "tries": cert.tries, "reason": cert.reason,
                         "wall_s": round(time.perf_counter() - t0, 2)})
    return rows


def shares(rows: list[dict]) -> list[tuple[str, str, int, dict[str, int]]]:
    """(dimension, value, scenes, certified per expert) for overall, level, suite, category."""
    from pipeline.records import Category, Level

    order = {"level": [lv.value for lv in Level], "category": [c.value for c in Category]}
    out = []
    groups: dict[tuple[str, str], dict[str, set]] = defaultdict(lambda: defaultdict(set))
    scenes: dict[tuple[str, str], set] = defaultdict(set)
    for r in rows:
        for dim, val in (("all", "all"), ("level", r["level"]), ("suite", r["suite"]), ("category", r["category"])):
            scenes[(dim, val)].add(r["scene"])
            if r["certified"]:
                groups[(dim, val)][r["expert"]].add(r["scene"])
    for dim in ("all", "level", "suite", "category"):
        vals = sorted({v for d, v in scenes if d == dim}, key=lambda v: (order.get(dim, []).index(v)
                                                                          if v in order.get(dim, []) else 99, v))
        for v in vals:
            out.append((dim, v, len(scenes[(dim, v)]), {e: len(groups[(dim, v)][e]) for e in EXPERTS}))
    return out


def pct(k: int, n: int) -> str:
    return f"{k}/{n} ({k / n:.0%})" if n else "—"


def markdown(table: list, reasons: Counter, note: str, experts: tuple[str, ...] = EXPERTS) -> str:
    lines = ["| group | scenes | plain expert | recovery expert | change |", "|---|---|---|---|---|"]
    for dim, val, n, c in table:
        name = "**all**" if dim == "all" else f"{dim}: {val}"
        cells = [pct(c[e], n) if e in experts else "-" for e in EXPERTS]  # an expert not run: no figure
        change = f"{(c['recovery'] - c['plain']) / n:+.0%}" if set(EXPERTS) <= set(experts) else "-"
        lines.append(f"| {name} | {n} | {cells[0]} | {cells[1]} | {change} |")
    why = ", ".join(f"{k} {v}" for k, v in reasons.most_common()) or "none"
    return "\n".join(lines) + f"\n\nRecovery expert, scenes not certified by reason: {why}.\n\n{note}\n"


def figure(table: list, path: Path, experts: tuple[str, ...] = EXPERTS) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    panels = [("level", "overall and per level"), ("suite", "per suite"), ("category", "per category")]
    widths = [1 + sum(d == dim for d, *_ in table) for dim, _ in panels]
    widths[1] -= 1
    widths[2] -= 1
    fig, axes = plt.subplots(1, 3, figsize=(3 + 0.75 * sum(widths), 4.2), gridspec_kw={"width_ratios": widths})
    for ax, (dim, title) in zip(axes, panels, strict=True):
        sel = [t for t in table if t[0] == dim or (dim == "level" and t[0] == "all")]
        x = np.arange(len(sel))
        for k, (e, colour) in enumerate(zip(EXPERTS, ("#b0b0b0", "#2a7fb8"), strict=True)):
            if e not in experts:
                continue
            vals = [100 * t[3][e] / t[2] if t[2] else 0 for t in sel]
            bars = ax.bar(x + (k - 0.5) * 0.4, vals, 0.4, label=f"{e} expert", color=colour)
            ax.bar_label(bars, labels=[f"{v:.0f}" for v in vals], fontsize=6)
        ax.set_xticks(x, [f"{t[1]}\n(n={t[2]})" for t in sel], fontsize=7, rotation=30 if dim == "category" else 0,
                      ha="right" if dim == "category" else "center")
        if dim == "level":  # the aims: 85% of all scenes, 70% in every level
            for i, t in enumerate(sel):
                ax.hlines(100 * (AIM_ALL if t[0] == "all" else AIM_LEVEL), i - 0.45, i + 0.45, color="k", lw=1,
                          ls="--")
        ax.set_ylim(0, 108)
        ax.set_title(title, fontsize=9)
    axes[0].set_ylabel("certified scenes %")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="upper right", ncol=2)
    fig.suptitle("Certified scenes: plain vs recovery expert (dashed: aim)", fontsize=10, x=0.02, ha="left")
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def release_folder(arg: Path) -> Path:
    for cand in (arg, arg / "release"):
        if (cand / "scenarios.parquet").is_file():
            return cand
    raise SystemExit(f"{arg}: no scenarios.parquet here or in {arg / 'release'} (run `recover release` first)")


def stage2_scenes(run: Path) -> tuple[Path, list[dict]]:
    """(root the paths are under, scene rows) of the scenes stage 2 chose in `run`."""
    import pyarrow.parquet as pq

    from pipeline.layout import RunLayout
    from pipeline.records import Characterization

    layout = RunLayout(run)
    table = layout.stage2.localizations_table
    if not table.is_file():
        raise SystemExit(f"{table}: not found (run stage 2 first)")
    rows = []
    for r in pq.read_table(table).to_pylist():
        if not r["scene_state"]:
            continue  # quarantined or no failure found: no scene
        label = layout.stage3.characterization(r["key"])
        char = Characterization.model_validate_json(label.read_text()) if label.is_file() else None
        rows.append({"scene": f"{r['key']}/step_{r['scene_step']:04d}", "suite": r["suite"], "task": r["task"],
                     "instruction": r["instruction"], "level": char.recovery_level.value if char else "unknown",
                     "category": char.failure_category.value if char else "unknown",
                     "bddl_path": r["scene_bddl"], "state_path": r["scene_state"]})
    return layout.stage2.root, rows


def release_scenes(arg: Path) -> tuple[Path, list[dict]]:
    """(release folder, scene rows) of a run's or a release folder's manifest."""
    from pipeline.release.manifest import read_manifest

    release = release_folder(arg)
    return release, [{"scene": f"{r.suite}/{r.task}/{r.episode_id}/step_{r.step:04d}", "suite": r.suite,
                      "task": r.task, "instruction": r.instruction, "level": r.level, "category": r.category,
                      "bddl_path": r.bddl_path, "state_path": r.state_path}
                     for r in read_manifest(release / "scenarios.parquet")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path, help="a run folder (with release/) or a release folder")
    ap.add_argument("--tries", type=int, default=2)
    from pipeline.config import Config

    # default: the release's own certificate horizon (= eval.horizon, what a policy gets)
    ap.add_argument("--horizon", type=int, default=Config().release.certify_horizon)
    ap.add_argument("--chunk", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT, help="output stem (.md, .json, .png)")
    ap.add_argument("--match", action="append", default=[],
                    help="only scenes whose id (suite/task/episode/step_NNNN) contains this text; repeatable")
    ap.add_argument("--experts", default=",".join(EXPERTS), help="comma-separated subset of: " + ", ".join(EXPERTS))
    ap.add_argument("--stage2", action="store_true", help="the scenes stage 2 chose (a run without a release)")
    args = ap.parse_args()
    experts = [e for e in args.experts.split(",") if e]
    if not experts or set(experts) - set(EXPERTS):
        raise SystemExit(f"--experts {args.experts!r}: choose from {', '.join(EXPERTS)}")

    release, rows = stage2_scenes(args.run) if args.stage2 else release_scenes(args.run)
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        if args.match and not any(m in r["scene"] for m in args.match):
            continue
        groups[(r["suite"], r["task"], (release / r["bddl_path"]).read_bytes())].append(r)
    units = [(str(release), g, e, args.tries, args.horizon, args.chunk) for g in groups.values() for e in experts]
    n_scenes = sum(len(g) for g in groups.values())
    if not n_scenes:
        raise SystemExit(f"{release}: no scene matches --match {args.match}")
    console = Console()
    results: list[dict] = []
    t0 = time.perf_counter()
    with Progress(console=console) as progress, ProcessPoolExecutor(args.workers) as pool:
        bar = progress.add_task("certificates", total=len(experts) * n_scenes)
        for f in as_completed([pool.submit(certify_unit, *u) for u in units]):
            results += f.result()
            progress.update(bar, completed=len(results))
    wall = time.perf_counter() - t0
    table = shares(results)
    reasons = Counter(r["reason"] for r in results if r["expert"] == "recovery" and not r["certified"])
    out = Table(title=f"certified scenes of {release} ({n_scenes} scenes)")
    for col in ("group", "scenes", "plain expert", "recovery expert", "change"):
        out.add_column(col)
    for dim, val, n, c in table:
        ran = [pct(c[e], n) if e in experts else "-" for e in EXPERTS]
        out.add_row("all" if dim == "all" else f"{dim}: {val}", str(n), *ran,
                    f"{(c['recovery'] - c['plain']) / n:+.0%}" if set(EXPERTS) <= set(experts) else "-")
    console.print(out)
    note = (f"{'Stage-2 scenes' if args.stage2 else 'Release'} `{release}`: {n_scenes} scenes; each expert up to {args.tries} tries, horizon {args.horizon}, "
            f"chunk {args.chunk}; {len(results)} certificates in {wall / 60:.1f} min on {args.workers} workers.")
    md = markdown(table, reasons, note, tuple(experts))
    console.print(f"recovery expert, not certified by reason: {dict(reasons.most_common())}")
    from pipeline.atomic import write_text

    write_text(args.out.with_suffix(".md"), f"# Certificate coverage: plain vs recovery expert\n\n{md}\n"
                                            f"![certified share]({args.out.with_suffix('.png').name})\n")
    write_text(args.out.with_suffix(".json"), json.dumps({"summary": [
        {"dimension": d, "value": v, "scenes": n, "certified": c} for d, v, n, c in table],
        "reasons": dict(reasons), "scenes": sorted(results, key=lambda r: (r["scene"], r["expert"]))}, indent=1))
    figure(table, args.out.with_suffix(".png"), tuple(experts))
    console.print(f"wrote {args.out.with_suffix('.md')}, .json, .png")


if __name__ == "__main__":
    main()
