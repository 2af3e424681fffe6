"""The recovery expert on books in the poses it finds hardest, made from the tuning states.

A report run's uncertified books lie upside down, on their side or on their face (README,
"Tuning protocol"); a tuning run has only a few of each. This makes more from LIBERO's own
init states 0-4 (the tuning states): for each of the 15 book tasks and init state, the goal
book is turned (`upside`: half a turn about its long edge; `side`: a quarter in its own
plane; `face`: a quarter about its long edge, onto a face), a seeded yaw about the vertical,
dropped where it stood (3 mm above the table) and settled; a pose that would overlap another
object is skipped. Each scene is certified as `recover release` does
(`pipeline.release.certify.certify_one`, recovery expert, up to `--tries` tries, horizon
`--horizon`, chunk 8), one process per scene on `--workers`. Prints certified per pose kind
with the reasons; writes markdown and per-scene JSON (`--out` stem).

    .venv/bin/python benchmarks/book_poses.py [--kinds upside side face] [--per-kind 8] \\
        [--workers 2] [--out benchmarks/results/book_poses]
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "book_poses"
KINDS = ("upside", "side", "face")
TUNING_INITS = range(5)  # the tuning protocol's states (README, "Tuning protocol")
DROP_M = 0.003  # lowest point above the table when the book is let fall
SETTLE_STEPS = 30


def _turn(kind: str, axes, rng: np.random.Generator):
    from scipy.spatial.transform import Rotation

    if kind == "upside":
        turn = Rotation.from_rotvec(axes.long * np.pi)
    elif kind == "side":
        turn = Rotation.from_rotvec(axes.thin * np.pi / 2 * rng.choice([-1.0, 1.0]))
    else:
        turn = Rotation.from_rotvec(axes.long * np.pi / 2 * rng.choice([-1.0, 1.0]))
    return Rotation.from_rotvec([0.0, 0.0, rng.uniform(-np.pi, np.pi)]) * turn


def make_scene(env, kind: str, rng: np.random.Generator) -> tuple[np.ndarray, str] | None:
    """The env's goal book turned into `kind` where it stands, settled: (state, book), or None
    when there is no standing goal book or the turned book would overlap another object."""
    from scipy.spatial.transform import Rotation

    from pipeline.policies.scripted.recovery.stand_book import book_axes
    from pipeline.policies.scripted.scene import Scene

    s = Scene(env)
    books = [c[1] for c in env.goal if len(c) == 3 and "book" in c[1]]
    if not books or (axes := book_axes(s, books[0])) is None or axes.up[2] < 0.98:
        return None
    book = books[0]
    turn = _turn(kind, axes, rng)
    at = 1 + env.free_joints()[book]  # the flattened state: time, qpos, qvel
    state = env.get_state()
    pos, (w, x, y, z) = state[at:at + 3].copy(), state[at + 3:at + 7]
    centre = s.box(book).centre
    state[at:at + 3] = centre + turn.apply(pos - centre)
    state[at + 3:at + 7] = np.roll((turn * Rotation.from_quat([x, y, z, w])).as_quat(), 1)
    env.set_state(state)
    state[at + 2] += s.table_height() + DROP_M - s.box(book).lo[2]
    env.set_state(state)
    box = s.box(book)
    for name, other in s.obstacle_boxes({book}):
        if name != "table" and np.all(other[0] < box.hi) and np.all(box.lo < other[1]):
            return None
    env.reanchor_controller()
    env.settle(SETTLE_STEPS)
    return env.get_state(), book


def certify_unit(suite: str, task: str, init: int, kind: str, seed: int, tries: int, horizon: int) -> dict | None:
    """Make one scene (init state `init`, pose `kind`, yaw from `seed`) and certify it."""
    from pipeline.release.certify import certify_one
    from pipeline.release.experts import recovery_expert
    from pipeline.sim import SimEnv, get_task

    with SimEnv(get_task(suite, task)) as env:
        env.reset_to_init(init)
        made = make_scene(env, kind, np.random.default_rng(seed))
        if made is None:
            return None
        state, book = made
        t0 = time.perf_counter()
        cert = certify_one(env, state, recovery_expert, tries, horizon, 8)
        return {"suite": suite, "task": task, "init": init, "kind": kind, "seed": seed, "book": book,
                "certified": cert.certified, "tries": cert.tries, "reason": cert.reason,
                "wall_s": round(time.perf_counter() - t0, 2)}


def plan(kinds: list[str], per_kind: int, seed: int) -> list[tuple[str, str, int, str, int]]:
    """(suite, task, init, kind, seed) units: per kind, `per_kind` (task, init) pairs drawn
    without repeats from the 15 book tasks x init states 0-4 (a skipped pose is not redrawn)."""
    from pipeline.sim.registry import all_tasks

    pairs = [(t.suite, t.name, i) for t in all_tasks() if "book" in t.name for i in TUNING_INITS]
    rng = np.random.default_rng(seed)
    units = []
    for k, kind in enumerate(kinds):
        for j in rng.choice(len(pairs), size=min(per_kind, len(pairs)), replace=False):
            suite, task, init = pairs[int(j)]
            units.append((suite, task, init, kind, seed * 1000 + k * 100 + int(j)))
    return units


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--per-kind", type=int, default=8)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--tries", type=int, default=2)
    ap.add_argument("--horizon", type=int, default=520)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    units = plan(args.kinds, args.per_kind, args.seed)
    rows, console = [], Console()
    with ProcessPoolExecutor(args.workers) as pool, Progress(console=console) as bar:
        task = bar.add_task("book poses", total=len(units))
        futures = [pool.submit(certify_unit, *u, args.tries, args.horizon) for u in units]
        for f in as_completed(futures):
            if (row := f.result()) is not None:
                rows.append(row)
            bar.advance(task)
    rows.sort(key=lambda r: (r["kind"], r["task"], r["init"]))
    by_kind = defaultdict(list)
    for r in rows:
        by_kind[r["kind"]].append(r)
    table = Table(title=f"recovery expert on turned books (init states 0-4, {args.tries} tries, "
                        f"horizon {args.horizon})")
    for col in ("pose", "scenes", "certified", "not certified, by reason"):
        table.add_column(col)
    lines = ["| pose | scenes | certified | not certified, by reason |", "|---|---|---|---|"]
    for kind in args.kinds:
        got = by_kind.get(kind, [])
        ok = sum(r["certified"] for r in got)
        why = dict(Counter(r["reason"] for r in got if not r["certified"]))
        cells = [kind, str(len(got)), f"{ok}/{len(got)}", json.dumps(why)]
        table.add_row(*cells)
        lines.append("| " + " | ".join(cells) + " |")
    console.print(table)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text("# Turned books: the recovery expert\n\n" + "\n".join(lines) + "\n")
    args.out.with_suffix(".json").write_text(json.dumps(rows, indent=1))
    console.print(f"wrote {args.out.with_suffix('.md')}, .json ({len(units) - len(rows)} poses skipped: overlap)")


if __name__ == "__main__":
    main()
