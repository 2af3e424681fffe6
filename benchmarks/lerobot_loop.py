"""The reference's loop in miniature, end to end: train on recoveries -> roll out -> evaluate.

    .venv/bin/python benchmarks/lerobot_loop.py --config <a run's config> [--steps 300] [--episodes 4]
        [--scenes 20] [--image-size 128] [--out DIR] [--json benchmarks/results/lerobot_loop.json]

On a run with a release and recovery demos (`recover release`, `recover demos`):
1. `recover export-lerobot --dataset recoveries` at `--image-size` (into `<out>/lerobot/`);
2. LeRobot's converter (v2.1 -> v3.0) and `lerobot-train`: a tiny ACT, `--steps` steps, CPU
   (`pipeline/policies/lerobot_train.py`); the loss of every 5th step is kept;
3. stage 1 with the checkpoint as failure generator (`policy.kind: lerobot`, LeRobot's
   PolicyServer): `--episodes` episodes, init state 0 of the tasks the demos came from, and
   stage 2 (the run's localizer) on its failures: the new restorable scenes;
4. `recover eval` of the clean scripted expert and the checkpoint side by side on the first
   `--scenes` eval scenes of the release, one trial each (gripper open, no RD, no official trials).
Prints and writes (JSON) the figures: training steps, loss at start and end, episodes and trials
with their successes, and the wall time of each step. The run folder itself is only read.
Threads: every LeRobot process gets OMP_NUM_THREADS=--threads (default 1: a shared machine).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, required=True)
    ap.add_argument("--out", type=Path, default=None, help="default <run>/lerobot_loop")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--batch-size", type=int, default=8)
    ap.add_argument("--chunk", type=int, default=16, help="ACT's chunk_size (the rollout executes chunk_size)")
    ap.add_argument("--image-size", type=int, default=128)
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--scenes", type=int, default=20)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--json", type=Path, default=Path("benchmarks/results/lerobot_loop.json"))
    args = ap.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[k] = str(args.threads)

    from pipeline.config import load_config
    from pipeline.eval.records import read_rows
    from pipeline.eval.run import run as run_eval
    from pipeline.policies.lerobot_train import tiny_act_args, train
    from pipeline.records import read_episodes
    from pipeline.release import lerobot_export
    from pipeline.release.recovery_demos import read_demos
    from pipeline.layout import RunLayout
    from pipeline.stage1.run import run as run_stage1
    from pipeline.stage2.run import run as run_stage2

    cfg = load_config(args.config)
    out = (args.out or cfg.out / "lerobot_loop").resolve()
    out.mkdir(parents=True, exist_ok=True)
    executor = cfg.executor.model_copy(update={"workers": args.workers})
    figures: dict = {"config": str(args.config), "run": str(cfg.out), "out": str(out), "threads": args.threads,
                     "workers": args.workers, "image_size": args.image_size}

    # 1. the recoveries dataset, exported at the policy's image size
    t0 = time.perf_counter()
    exp_cfg = cfg.model_copy(update={"executor": executor, "release": cfg.release.model_copy(
        update={"lerobot_image_size": args.image_size, "lerobot_dir": out / "lerobot"})})
    lerobot_export.run(exp_cfg, only=["recoveries"])
    info = json.loads((out / "lerobot/recoveries/meta/info.json").read_text())
    figures["export"] = {"episodes": info["total_episodes"], "frames": info["total_frames"],
                         "wall_s": round(time.perf_counter() - t0, 1)}
    print("export:", figures["export"], flush=True)

    # 2. train a tiny ACT with lerobot-train
    res = train(out / "lerobot/recoveries", out / "act", steps=args.steps, batch_size=args.batch_size,
                policy_args=tiny_act_args(args.chunk), threads=args.threads, log_freq=5)
    losses = res.losses
    figures["train"] = {"steps": args.steps, "batch_size": args.batch_size, "policy": "act (tiny_act_args)",
                        "checkpoint": str(res.checkpoint), "loss_start": losses[0] if losses else None,
                        "loss_end": losses[-1] if losses else None,
                        "loss_min": min(losses, key=lambda x: x[1]) if losses else None,
                        "losses": losses, "wall_convert_s": res.wall_convert_s, "wall_train_s": res.wall_train_s,
                        "command": " ".join(res.command)}
    print("train:", {k: v for k, v in figures["train"].items() if k not in ("losses", "command")}, flush=True)
    policy = {"kind": "lerobot", "name": "act-recoveries",
              "lerobot": {"path": str(res.checkpoint), "image_size": args.image_size}}

    # 3. stage 1: the checkpoint as failure generator, init state 0 of the demos' tasks
    demo_tasks = list(dict.fromkeys((d.suite, d.task) for d in read_demos(RunLayout.of(cfg).recoveries.demos)))
    chosen = demo_tasks[: args.episodes]
    t0 = time.perf_counter()
    gen = cfg.model_validate({**cfg.model_dump(mode="json"), "run": {**cfg.run.model_dump(mode="json"),
                                                                     "output_dir": str(out / "gen")},
                              "executor": executor.model_dump(mode="json"),
                              "tasks": {"suites": sorted({s for s, _ in chosen}), "tasks": [t for _, t in chosen],
                                        "init_states": [0]},
                              "stage1": {**cfg.stage1.model_dump(mode="json"), "policy": policy,
                                         "video": {**cfg.stage1.video.model_dump(mode="json"), "render": "none"}}})
    s1 = run_stage1(gen)
    eps = read_episodes(RunLayout.of(gen).stage1.manifest)
    figures["stage1"] = {"episodes": len(eps), "succeeded": sum(e.success for e in eps),
                         "failed": sum(not e.success for e in eps), "errors": len(s1["errors"]),
                         "steps": [e.steps for e in eps], "tasks": [f"{e.suite}/{e.task}" for e in eps],
                         "wall_s": round(time.perf_counter() - t0, 1)}
    print("stage 1:", figures["stage1"], flush=True)
    # ... and stage 2 on its failures: the restorable scenes they give (the loop's "more failures")
    t0 = time.perf_counter()
    s2 = run_stage2(gen)
    figures["stage2"] = {"scenes": s2.get("scenes"), "quarantined": s2.get("quarantine_reasons"),
                         "onset_kinds": s2.get("onset_kinds"), "wall_s": round(time.perf_counter() - t0, 1)}
    print("stage 2:", figures["stage2"], flush=True)

    # 4. recover eval: the clean scripted expert and the checkpoint on the release's eval scenes
    t0 = time.perf_counter()
    ev = cfg.model_validate({**cfg.model_dump(mode="json"), "run": {**cfg.run.model_dump(mode="json"),
                                                                    "output_dir": str(out / "evalrun")},
                             "executor": executor.model_dump(mode="json"),
                             "eval": {**cfg.eval.model_dump(mode="json"),
                                      "policies": [{"kind": "scripted", "name": "expert"}, policy],
                                      "scenes_dir": str(RunLayout.of(cfg).release.root), "split": "eval",
                                      "max_scenes": args.scenes, "trials_per_condition": 1,
                                      "gripper_conditions": ["open"], "rd": False, "official_trials": 0}})
    run_eval(ev)
    rows = read_rows(RunLayout.of(ev).eval.episodes)
    per = {}
    for r in rows:
        p = per.setdefault(r.policy, {"kind": r.policy_kind, "trials": 0, "successes": 0, "scenes": set()})
        p["trials"] += 1
        p["successes"] += int(r.success)
        p["scenes"].add(r.scene_id)
    figures["eval"] = {"report": str(RunLayout.of(ev).eval.report), "wall_s": round(time.perf_counter() - t0, 1),
                       "policies": {k: {**v, "scenes": len(v["scenes"]),
                                        "rsr": round(v["successes"] / v["trials"], 3) if v["trials"] else None}
                                    for k, v in per.items()}}
    print("eval:", figures["eval"], flush=True)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(figures, indent=2) + "\n")
    print(f"figures -> {args.json}")
    return figures


if __name__ == "__main__":
    main()
