"""The fast control step against robosuite's `env.step`, bit for bit, in every suite.

    .venv/bin/python benchmarks/step_identity.py [--full] [--tasks-per-suite 1] [--init 0]

For the first task(s) of each of the five suites, plays random actions and the scripted
expert with stage 1's smoke noise once through robosuite's step and once through
`FastStepper`, from the same init state, and compares every flattened state (as bits) and
every goal flag. Default: 300 steps each (what `make test` checks, a bit longer); `--full`:
full 520-step episodes (LIBERO's longest horizon). Exits 1 on any difference.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

from pipeline.config import ScriptedNoise, ScriptedPolicyConfig  # noqa: E402
from pipeline.policies.scripted import make_scripted_policy  # noqa: E402
from pipeline.sim import SimEnv, tasks  # noqa: E402
from pipeline.sim.step_check import compare, expert_episode  # noqa: E402

SUITES = ["libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90"]
NOISE = ScriptedNoise(grasp_offset_m=0.02, approach_height_m=0.015, gripper_timing_steps=6, action_noise=0.2,
                      speed_scale=0.5, place_offset_m=0.03)  # configs/smoke.yaml's


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="full 520-step episodes")
    ap.add_argument("--tasks-per-suite", type=int, default=1)
    ap.add_argument("--init", type=int, default=0, help="init state index")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    steps = 520 if args.full else 300
    failed = 0
    print(f"{steps} steps per episode; states compared as bits after every step")
    for suite in SUITES:
        for task in tasks([suite])[: args.tasks_per_suite]:
            t0 = time.perf_counter()
            with SimEnv(task) as env:
                rng = np.random.default_rng(args.seed)
                random = compare(env, args.init, rng.uniform(-1, 1, (steps, 7)))
                policy = make_scripted_policy(ScriptedPolicyConfig(noise=NOISE))
                played = expert_episode(env, policy, args.init, steps, args.seed)
                expert = compare(env, args.init, played.actions, reference=played)
            for label, c in (("random", random), ("expert+noise", expert)):
                verdict = "identical" if c.identical else (
                    f"DIFFERENT (first state mismatch {c.first_state_mismatch}, goal {c.first_goal_mismatch})")
                print(f"  {task.task_id:<60} {label:<13} {c.steps} steps, goal held on {c.successes:3d}: {verdict}",
                      flush=True)
                failed += not c.identical
            print(f"    ({time.perf_counter() - t0:.0f} s)", flush=True)
    print("all identical" if not failed else f"{failed} episode(s) differ")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
