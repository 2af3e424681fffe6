"""How often and how the failure generator fails: one column per run folder, side by side.

For each run (stage 1 done, scripted generator): the failure rate overall and per suite, and,
from the generator's own truth (`truth.parquet`, `pipeline/truth/derive.py`), the outcome of
the first failed attempt (missed grasp, dropped, misplaced, knocked, ...), the expected
category and level of every failed episode, overall and per suite. Used to tune the default
noise so that about half of the episodes fail, in varied ways, and to show what a change of the
expert did to the mix.

The generator's reach: every task's share of failing episodes, and the task groups (a suite's
scene, e.g. libero_90 KITCHEN_SCENE3, and the instruction's verb, e.g. "open") whose episodes
almost never fail (below `--rare`, default 15%), with at least `--min-group` episodes. A figure
shows per suite the failure rate and one dot per task.

    .venv/bin/python benchmarks/failure_mix.py RUN_BEFORE RUN_AFTER [--names old new] [--out STEM]

Writes STEM.md, STEM.json and STEM.png (default benchmarks/results/failure_mix).
"""

from __future__ import annotations

import argparse
import json
import re
from collections import Counter, defaultdict
from pathlib import Path

from rich.console import Console
from rich.table import Table

from pipeline.layout import RunLayout
from pipeline.records import read_episodes
from pipeline.truth.bench import load_truths

REPO = Path(__file__).resolve().parents[1]


def groups(suite: str, task: str, instruction: str) -> list[str]:
    """The task's scene within its suite (LIBERO-90/10 name scenes; the other suites are one
    scene each) and the instruction's verb."""
    scene = re.match(r"^([A-Z_]+_SCENE\d+)_", task)
    verb = instruction.split()[0].lower() if instruction else "?"
    return [f"{suite} {scene.group(1) if scene else 'all'}", f"{suite} '{verb}'"]


def mix(run: Path) -> dict:
    failed, truths, aside = load_truths(run)
    episodes = read_episodes(RunLayout(run).stage1.manifest)
    per_suite = Counter(r.suite for r in episodes)
    fail_suite = Counter(r.suite for r in failed)
    suite_of = {r.key: r.suite for r in failed}
    by_suite: dict[str, dict[str, Counter]] = defaultdict(lambda: {"outcome": Counter(), "level": Counter()})
    for key, t in truths.items():
        by_suite[suite_of[key]]["outcome"][t.outcome] += 1
        by_suite[suite_of[key]]["level"][t.level] += 1
    tasks: dict[str, list] = {}
    grp: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for r in episodes:
        row = tasks.setdefault(f"{r.suite}/{r.task}", [0, 0, r.suite])
        row[0] += not r.success
        row[1] += 1
        for g in groups(r.suite, r.task, r.instruction):
            grp[g][0] += not r.success
            grp[g][1] += 1
    return {
        "episodes": len(episodes),
        "failed": len(failed),
        "suites": {s: [fail_suite[s], n] for s, n in sorted(per_suite.items())},
        "outcome": dict(Counter(t.outcome for t in truths.values()).most_common()),
        "category": dict(Counter(t.category for t in truths.values()).most_common()),
        "level": dict(sorted(Counter(t.level for t in truths.values()).items())),
        "by_suite": {s: {k: dict(sorted(c.items())) for k, c in v.items()} for s, v in sorted(by_suite.items())},
        "tasks": tasks,
        "groups": {g: v for g, v in sorted(grp.items())},
        "no_truth": len(aside),
    }


def rare_groups(m: dict, rare: float, min_group: int) -> list[tuple[str, int, int]]:
    return [(g, f, n) for g, (f, n) in m["groups"].items() if n >= min_group and f / n < rare]


def figure(mixes: list[dict], names: list[str], path: Path) -> None:
    """Per suite: the failure rate (bar) and every task's share of failing episodes (dots)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    suites = sorted({s for m in mixes for s in m["suites"]})
    fig, ax = plt.subplots(figsize=(2 + 1.6 * len(suites), 3.6))
    width = 0.8 / len(mixes)
    rng = np.random.default_rng(0)  # jitter only, so the dots of one share do not overlap
    for k, (m, name) in enumerate(zip(mixes, names, strict=True)):
        x0 = np.arange(len(suites)) + (k - (len(mixes) - 1) / 2) * width
        rates = [100 * m["suites"].get(s, [0, 1])[0] / max(m["suites"].get(s, [0, 1])[1], 1) for s in suites]
        bars = ax.bar(x0, rates, width * 0.9, alpha=0.45, label=f"{name}: failure rate")
        ax.bar_label(bars, labels=[f"{r:.0f}" for r in rates], fontsize=7)
        for i, s in enumerate(suites):
            shares = [100 * f / n for f, n, su in m["tasks"].values() if su == s]
            ax.scatter(x0[i] + rng.uniform(-0.3, 0.3, len(shares)) * width, shares, s=6, color="k", alpha=0.5)
    ax.set_xticks(np.arange(len(suites)), suites, fontsize=8)
    ax.set_ylabel("failing episodes %")
    ax.set_ylim(-3, 105)
    ax.set_title("failure generator: rate per suite (bars), share per task (dots)", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def rows(mixes: list[dict]) -> list[tuple[str, list[str]]]:
    out = [("failed", [f"{m['failed']}/{m['episodes']} ({m['failed'] / max(m['episodes'], 1):.0%})" for m in mixes])]
    for s in sorted({s for m in mixes for s in m["suites"]}):
        out.append((f"failed: {s}", [f"{m['suites'].get(s, [0, 0])[0]}/{m['suites'].get(s, [0, 0])[1]}" for m in mixes]))
    for part in ("outcome", "category", "level"):
        keys = {k for m in mixes for k in m[part]}
        # levels in order; outcomes and categories most frequent first
        order = sorted(keys) if part == "level" else sorted(keys, key=lambda k: -sum(m[part].get(k, 0) for m in mixes))
        for k in order:
            out.append((f"{part}: {k}", [str(m[part].get(k, 0)) for m in mixes]))
    for s in sorted({s for m in mixes for s in m["by_suite"]}):
        for part in ("outcome", "level"):
            cells = [", ".join(f"{k} {v}" for k, v in m["by_suite"].get(s, {}).get(part, {}).items()) or "-"
                     for m in mixes]
            out.append((f"{s}: {part}s", cells))
    out.append(("failed without a usable truth", [str(m["no_truth"]) for m in mixes]))
    return out


def side_by_side(title: str, names: list[str], body: list[tuple[str, list[str]]]) -> list[str]:
    """Print `body` (a label and one cell per run) as a table with one column per run; its
    markdown lines."""
    table = Table(title=title)
    table.add_column("")
    for n in names:
        table.add_column(n, justify="right")
    for label, cells in body:
        table.add_row(label, *cells)
    Console().print(table)
    md = ["| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    return md + [f"| {label} | " + " | ".join(cells) + " |" for label, cells in body]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--names", nargs="+", default=None)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "failure_mix")
    ap.add_argument("--rare", type=float, default=0.15, help="a group failing less often than this is listed")
    ap.add_argument("--min-group", type=int, default=4, help="episodes a group needs to be listed")
    a = ap.parse_args()
    names = a.names or [r.name for r in a.runs]
    if len(names) != len(a.runs):
        ap.error("--names needs one name per run")
    mixes = [mix(r) for r in a.runs]
    md = side_by_side("failure generator: rate and kinds (truth of the first failed attempt)", names, rows(mixes))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    for name, m in zip(names, mixes, strict=True):
        rare = rare_groups(m, a.rare, a.min_group)
        never = sorted(t for t, (f, n, _) in m["tasks"].items() if f == 0)
        line = (f"{name}: {len(never)}/{len(m['tasks'])} tasks never failed; groups failing < {a.rare:.0%} "
                f"(>= {a.min_group} episodes): " + (", ".join(f"{g} {f}/{n}" for g, f, n in rare) or "none"))
        Console().print(line)
        md.append(f"\n{line}")
    a.out.with_suffix(".md").write_text("\n".join(md) + "\n")
    a.out.with_suffix(".json").write_text(json.dumps(dict(zip(names, mixes)), indent=2))
    figure(mixes, names, a.out.with_suffix(".png"))
    Console().print(f"wrote {a.out.with_suffix('.md')}, .json, .png")


if __name__ == "__main__":
    main()
