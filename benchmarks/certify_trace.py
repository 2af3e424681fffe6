"""Why the recovery expert did (not) certify one scene: its attempt, phase by phase.

Replays the recovery expert's first try from one released (or stage-2) scene, as
`certify_one` runs it (zero noise, horizon, chunk), and prints one row per phase (the
primitive's label): the step it began, how many steps it took, the hand's position at its
start and what the robot touched during it (counted in steps), then the outcome. Writes the
rows as markdown and JSON, and with `--frames` a PNG strip of the agent and wrist views at
the given steps (`--out` stem). The scene key is the one the report table lists
(`suite/task/episode@step`) or a stage-2 path tail (`suite/task/episode/step_0123`).

    .venv/bin/python benchmarks/certify_trace.py runs/report17 \\
        'libero_90/KITCHEN_SCENE4_put_the_wine_bottle_on_the_wine_rack/scripted-i01-s1540159814@80' \\
        [--horizon 520] [--frames 1 100 200] [--out benchmarks/results/certify_trace]

`RECOVERY_DEBUG=1` also prints the planner's decisions (subgoal, rule) as they are taken.
"""

from __future__ import annotations

import argparse
import json
import re
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "certify_trace"
TOP_CONTACTS = 3  # things touched per phase shown, most steps first


@dataclass
class Phase:
    label: str
    start: int
    steps: int = 0
    eef: list[float] = field(default_factory=list)  # hand position at the phase's start (m)
    touched: dict[str, int] = field(default_factory=dict)  # thing the robot touched -> steps


def scene_key(key: str) -> tuple[str, str, str, int]:
    """(suite, task, episode, step) of `suite/task/episode@step` or `.../episode/step_0123`."""
    m = re.fullmatch(r"([^/]+)/([^/]+)/([^/@]+)(?:@(\d+)|/step_(\d+))", key.strip())
    if m is None:
        raise SystemExit(f"scene key {key!r}: expected suite/task/episode@step or suite/task/episode/step_0123")
    return m[1], m[2], m[3], int(m[4] or m[5])


def state_file(run: Path, suite: str, task: str, episode: str, step: int) -> Path:
    """The scene's MuJoCo state in the run's release, else in its stage-2 output."""
    tail = Path(f"selected_bddl_scenes_{suite}") / task / f"episode_{episode}" / f"step_{step:04d}_sim_state.npy"
    for base in (run / "release", run / "stage2", run):
        if (base / tail).is_file():
            return base / tail
    raise SystemExit(f"{run}: no state for {suite}/{task}/{episode}@{step} (looked for {tail} under release/, stage2/)")


def row(p: Phase) -> list[str]:
    """The phase's cells: start step, label, steps, hand position, the things touched most."""
    top = ", ".join(f"{k} {v}" for k, v in Counter(p.touched).most_common(TOP_CONTACTS))
    return [str(p.start), p.label, str(p.steps), " ".join(f"{v:+.3f}" for v in p.eef), top]


def trace(env, state: np.ndarray, horizon: int, chunk: int, frame_steps: list[int]):
    """Phases, the attempt's outcome and the frames at `frame_steps` (agentview over the wrist camera)."""
    from pipeline.release.experts import attempt, recovery_expert

    policy = recovery_expert(env, 0, 0.0)
    phases: list[Phase] = []
    frames: list[np.ndarray] = []

    def on_step(info) -> None:
        label = policy.phase or "-"
        if not phases or phases[-1].label != label:
            phases.append(Phase(label, info.step, eef=[round(float(v), 3) for v in env.eef_pose()[0]]))
        p = phases[-1]
        p.steps += 1
        for a, b in env.contacts():
            if "robot" in (a, b) and a != b:
                other = b if a == "robot" else a
                p.touched[other] = p.touched.get(other, 0) + 1
        if info.step in frame_steps:
            frames.append(np.concatenate([env.render("agentview", 256), env.render("robot0_eye_in_hand", 256)], axis=0))

    out = attempt(env, state, policy, 0, horizon, chunk, on_step=on_step)
    return phases, out, frames


def main(argv: list[str] | None = None) -> None:
    from pipeline.config import Config

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path, help="a run folder (with release/ or stage2/)")
    ap.add_argument("scene", help="suite/task/episode@step (as report_table.py lists it) or suite/task/episode/step_0123")
    ap.add_argument("--horizon", type=int, default=Config().release.certify_horizon)
    ap.add_argument("--chunk", type=int, default=8)
    ap.add_argument("--frames", type=int, nargs="*", default=[], help="steps to render into a PNG strip")
    ap.add_argument("--out", type=Path, default=OUT, help="output stem (.md, .json, .png)")
    args = ap.parse_args(argv)

    from pipeline.sim import build_env, get_task

    suite, task, episode, step = scene_key(args.scene)
    state = np.load(state_file(args.run, suite, task, episode, step))
    with build_env(get_task(suite, task)) as env:
        phases, out, frames = trace(env, state, args.horizon, args.chunk, sorted(set(args.frames)))

    console = Console()
    columns = ("step", "phase", "steps", "hand at start (m)", "the robot touched (steps)")
    table = Table(*columns, title=f"{suite}/{task}/{episode}@{step}: recovery expert, first try")
    rows = [row(p) for p in phases]
    for cells in rows:
        table.add_row(*cells)
    console.print(table)
    verdict = "certified" if out.success else f"not certified: {out.reason}"
    console.print(f"{verdict} after {out.steps} steps (horizon {args.horizon})")

    args.out.parent.mkdir(parents=True, exist_ok=True)
    record = {"scene": f"{suite}/{task}/{episode}@{step}", "success": bool(out.success), "reason": out.reason,
              "steps": int(out.steps), "horizon": args.horizon, "phases": [asdict(p) for p in phases]}
    args.out.with_suffix(".json").write_text(json.dumps(record, indent=1))
    lines = [f"# {record['scene']}", "", f"{verdict} after {out.steps} steps (horizon {args.horizon})", "",
             "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    if frames:
        from PIL import Image

        Image.fromarray(np.concatenate(frames, axis=1)).save(args.out.with_suffix(".png"))
    console.print(f"wrote {args.out}.md, .json" + (", .png" if frames else ""))


if __name__ == "__main__":
    main()
