"""How often and how the failure generator fails: one column per run folder, side by side.

For each run (stage 1 done, scripted generator): the failure rate overall and per suite, and,
from the generator's own truth (`truth.parquet`, `pipeline/truth/derive.py`), the outcome of
the first failed attempt (missed grasp, dropped, misplaced, knocked, ...), the expected
category and level of every failed episode. Used to tune the default noise so that about half
of the episodes fail, in varied ways, and to show what a change of the expert did to the mix.

    .venv/bin/python benchmarks/failure_mix.py RUN_BEFORE RUN_AFTER [--names old new] [--out STEM]

Writes STEM.md and STEM.json (default benchmarks/results/failure_mix).
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

from rich.console import Console
from rich.table import Table

from pipeline.layout import RunLayout
from pipeline.records import read_episodes
from pipeline.truth.bench import load_truths

REPO = Path(__file__).resolve().parents[1]


def mix(run: Path) -> dict:
    failed, truths, aside = load_truths(run)
    episodes = read_episodes(RunLayout(run).stage1.manifest)
    per_suite = Counter(r.suite for r in episodes)
    fail_suite = Counter(r.suite for r in failed)
    return {
        "episodes": len(episodes),
        "failed": len(failed),
        "suites": {s: [fail_suite[s], n] for s, n in sorted(per_suite.items())},
        "outcome": dict(Counter(t.outcome for t in truths.values()).most_common()),
        "category": dict(Counter(t.category for t in truths.values()).most_common()),
        "level": dict(sorted(Counter(t.level for t in truths.values()).items())),
        "no_truth": len(aside),
    }


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
    out.append(("failed without a usable truth", [str(m["no_truth"]) for m in mixes]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--names", nargs="+", default=None)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "failure_mix")
    a = ap.parse_args()
    names = a.names or [r.name for r in a.runs]
    if len(names) != len(a.runs):
        ap.error("--names needs one name per run")
    mixes = [mix(r) for r in a.runs]
    table = Table(title="failure generator: rate and kinds (truth of the first failed attempt)")
    table.add_column("")
    for n in names:
        table.add_column(n, justify="right")
    body = rows(mixes)
    for label, cells in body:
        table.add_row(label, *cells)
    Console().print(table)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    md = ["| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    md += [f"| {label} | " + " | ".join(cells) + " |" for label, cells in body]
    a.out.with_suffix(".md").write_text("\n".join(md) + "\n")
    a.out.with_suffix(".json").write_text(json.dumps(dict(zip(names, mixes)), indent=2))


if __name__ == "__main__":
    main()
