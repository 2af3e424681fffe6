"""Cost of stage 2's evidence replay per logged state, measured side by side in one run.

Replays `--steps` states of a real episode (the official init state, then random arm
actions) in one environment and times, per state:
    restore   SimEnv.set_state (LIBERO's set_init_state: set, forward, observables)
    evidence  compute_evidence (restore + poses, speeds, contacts, grasp, goal predicates)
and prints ms per state, seconds per 520-step episode, and the ratio evidence / restore.
Usage: .venv/bin/python benchmarks/stage2_evidence.py [--steps 520] [--task-index 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=520)
    ap.add_argument("--task-index", type=int, default=0)
    args = ap.parse_args()
    from pipeline.evidence import compute_evidence
    from pipeline.sim import build_env, tasks

    env = build_env(tasks(["libero_spatial"])[args.task_index])
    rng = np.random.default_rng(0)
    env.reset_to_init(0)
    states, grip = [env.get_state()], []
    for _ in range(args.steps):
        a = np.concatenate([rng.uniform(-0.5, 0.5, 6), [rng.choice([-1.0, 1.0])]])
        env.step(a)
        states.append(env.get_state())
        grip.append(a[6])
    states = np.asarray(states)
    t0 = time.perf_counter()
    for s in states:
        env.set_state(s)
    restore = (time.perf_counter() - t0) / len(states)
    t0 = time.perf_counter()
    compute_evidence(env, states, np.asarray(grip))
    evidence = (time.perf_counter() - t0) / len(states)
    env.close()
    print(f"states replayed: {len(states)}")
    print(f"restore   {restore * 1e3:6.2f} ms/state  {restore * 521:5.2f} s per 520-step episode")
    print(f"evidence  {evidence * 1e3:6.2f} ms/state  {evidence * 521:5.2f} s per 520-step episode")
    print(f"ratio evidence/restore: {evidence / restore:.1f}x")


if __name__ == "__main__":
    main()
