"""Success of the scripted expert per suite, at zero noise and at the default noise.

Runs `pipeline.rollout.run_episode` (horizon 520, chunk 8, 10 settle steps, as stage 1
does) over chosen suites, tasks and official init states, once with all noise levels at
zero (the clean expert) and once as configured in `stage1.policy.scripted` (noise and
retry limit; default: configs/default.yaml). Work units are (task, noise setting); a process
pool (one worker per core) builds one environment per unit and reuses it for the unit's
episodes. Prints a rich table and writes it as markdown (and the per-episode rows as
JSON) to benchmarks/results/.

    .venv/bin/python benchmarks/scripted_success.py \\
        [--suites libero_spatial libero_object libero_goal] [--init-states 0 1 2] \\
        [--tasks-per-suite N] [--workers 2] [--config configs/default.yaml] [--seed 0] \\
        [--expert plain|recovery] [--tasks 3 7]

`--expert recovery` measures the closed-loop recovery expert
(`pipeline.policies.scripted.recovery`) at zero noise only (it has no noise setting); its
episodes also record the expert's give-up reason.
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
OUT = REPO / "benchmarks" / "results"


def run_unit(suite: str, index: int, init_states: list[int], scripted: dict, seed: int,
             expert: str = "plain") -> list[dict]:
    """All episodes of one task at one noise setting, in one environment."""
    from pipeline.config import ScriptedPolicyConfig
    from pipeline.policies.scripted import make_scripted_policy
    from pipeline.policies.scripted.recovery import make_recovery_expert
    from pipeline.rollout import run_episode
    from pipeline.sim import build_env, tasks

    task = tasks([suite])[index]
    env = build_env(task)
    if expert == "recovery":
        policy = make_recovery_expert(env, task)
    else:
        policy = make_scripted_policy(ScriptedPolicyConfig.model_validate(scripted))
    noise = scripted["noise"]
    rows = []
    try:
        for i in init_states:
            env.reset_to_init(i)
            env.settle(10)
            policy.reset(task, seed + i)
            t0 = time.perf_counter()
            res = run_episode(env, policy, horizon=520, chunk_size=8)
            rows.append(
                {
                    "suite": suite,
                    "task": index,
                    "name": task.name,
                    "init": i,
                    "noisy": any(noise.values()),
                    "success": res.success,
                    "steps": res.steps,
                    "wall_s": round(time.perf_counter() - t0, 2),
                    "unmet": [list(c) for c, ok in env.goal_conjuncts() if not ok],
                    "events": policy.events,
                    "give_up": str(policy.reason_after(res.success) or "") if expert == "recovery" else "",
                }
            )
    finally:
        env.close()
        policy.close()
    return rows


def summarise(rows: list[dict]) -> list[dict]:
    by = defaultdict(list)
    for r in rows:
        by[r["suite"]].append(r)
    out = []
    for suite, rs in by.items():
        line = {"suite": suite, "tasks": len({r["task"] for r in rs})}
        for noisy, key in ((False, "zero"), (True, "default")):
            sel = [r for r in rs if r["noisy"] == noisy]
            ok = [r for r in sel if r["success"]]
            line[f"{key}_episodes"] = len(sel)
            line[f"{key}_success"] = len(ok) / len(sel) if sel else float("nan")
            line[f"{key}_steps"] = sum(r["steps"] for r in ok) / len(ok) if ok else float("nan")
        out.append(line)
    return out


def markdown(summary: list[dict], note: str) -> str:
    head = "| suite | tasks | episodes (each noise) | success, zero noise | success, default noise | mean steps of successes (zero / default) |"
    lines = [head, "|---|---|---|---|---|---|"]
    for s in summary:
        noisy = f"{s['default_success']:.0%}" if s["default_episodes"] else "-"  # none: recovery expert
        lines.append(
            f"| {s['suite']} | {s['tasks']} | {s['zero_episodes']} | {s['zero_success']:.0%} | "
            f"{noisy} | {s['zero_steps']:.0f} / {s['default_steps']:.0f} |"
        )
    return "\n".join(lines) + f"\n\n{note}\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suites", nargs="+", default=["libero_spatial", "libero_object", "libero_goal"])
    ap.add_argument("--init-states", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--tasks-per-suite", type=int, default=None, help="first N tasks of each suite")
    ap.add_argument("--task-stride", type=int, default=1, help="every k-th task (sampling libero_90)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--config", default=str(REPO / "configs" / "default.yaml"))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="default benchmarks/results/scripted_success[_recovery]")
    ap.add_argument("--expert", choices=["plain", "recovery"], default="plain")
    ap.add_argument("--tasks", nargs="+", type=int, default=None, help="only these task indices")
    args = ap.parse_args()
    if args.out is None:
        args.out = str(OUT / ("scripted_success" if args.expert == "plain" else "scripted_success_recovery"))

    from pipeline.config import load_config
    from pipeline.sim import tasks

    scripted = load_config(args.config).stage1.policy.scripted.model_dump()
    noise = scripted["noise"]
    zero = {**scripted, "noise": {k: 0 for k in noise}, "noise_by_suite": {}}
    units = []
    for suite in args.suites:
        chosen = tasks([suite])[:: args.task_stride][: args.tasks_per_suite]
        if args.tasks is not None:
            chosen = [t for t in chosen if t.index in args.tasks]
        for t in chosen:
            for levels in (zero, scripted) if args.expert == "plain" else (zero,):
                units.append((suite, t.index, args.init_states, levels, args.seed, args.expert))
    n_eps = len(units) * len(args.init_states)
    rows: list[dict] = []
    t0 = time.perf_counter()
    console = Console()
    with Progress(console=console) as progress, ProcessPoolExecutor(args.workers) as pool:
        bar = progress.add_task("episodes", total=n_eps)
        futures = [pool.submit(run_unit, *u) for u in units]
        for f in as_completed(futures):
            rows.extend(f.result())
            ok = sum(r["success"] for r in rows)
            progress.update(bar, completed=len(rows), description=f"episodes (success {ok}/{len(rows)})")
    wall = time.perf_counter() - t0
    summary = summarise(rows)
    table = Table(title=f"scripted expert ({args.expert}): success per suite")
    for col in ("suite", "tasks", "episodes", "zero noise", "default noise", "mean steps (0 / default)"):
        table.add_column(col)
    for s in summary:
        table.add_row(
            s["suite"], str(s["tasks"]), str(s["zero_episodes"]), f"{s['zero_success']:.0%}",
            f"{s['default_success']:.0%}", f"{s['zero_steps']:.0f} / {s['default_steps']:.0f}",
        )
    console.print(table)
    note = (
        f"Init states {args.init_states}; task stride {args.task_stride}, tasks per suite "
        f"{args.tasks_per_suite or 'all'}; seed {args.seed}; configured policy {scripted}; horizon 520, "
        f"chunk 8, settle 10; {len(rows)} episodes in {wall / 60:.1f} min on {args.workers} workers."
    )
    kinds = Counter(e.split(":")[0] for r in rows if r["noisy"] for e in r["events"])
    fails = sum(1 for r in rows if r["noisy"] and not r["success"])
    if args.expert == "plain":
        note += f"\nWith the configured noise: {fails} failed episodes; expert-observed events {dict(kinds)}."
    else:
        reasons = Counter(r["give_up"] for r in rows if not r["success"])
        failed = [f"{r['suite']}/{r['task']}@{r['init']}" for r in rows if not r["success"]]
        note = f"Recovery expert (zero noise). {note}\nFailures by reason {dict(reasons)}: {failed}."
    md = markdown(summary, note)
    print(md)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    from pipeline.atomic import write_text

    write_text(out.with_suffix(".md"), md)
    write_text(out.with_suffix(".json"), json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
