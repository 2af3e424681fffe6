"""CPU cost of one stage-1 video frame per render option, and what each option does to the picture.

    .venv/bin/python benchmarks/render_cost.py [--suite libero_spatial] [--task-index 0] [--rounds 3]

One episode of the smoke config's policy (160 steps, no early stop) gives the states of a
4-fps video; each option then renders those frames of both cameras at 256 px in a fresh
process, as stage 1's render process does (pipeline/sim/state_render.py, from the saved
model), warm (renderer built, one pass first), and reports process CPU time per frame
(`time.process_time`: every thread, llvmpipe's included), the H.264 encode per frame, and
the mean pixel difference against the stage's default. CPU time, not wall time: the
numbers hold on a busy machine. Rounds alternate the options so drifting load spreads evenly.

Options: the default (fast quality, geoms outside the view culled), the same without
culling (the code before), with LP_NUM_THREADS=1 and =0 (Mesa's llvmpipe threads; read once
per process), LIBERO's standard quality, and the default with the translucent collision
boxes hidden (robosuite draws them at alpha 0.3 in geom group 0; a picture change, not
adopted).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

CAMERAS = ["agentview", "robot0_eye_in_hand"]
SIZE, FPS = 256, 4
OPTIONS = {  # name -> (extra environment, child options)
    "default (fast, culled)": ({}, {}),
    "fast, not culled (before)": ({}, {"cull": False}),
    "default, LP_NUM_THREADS=1": ({"LP_NUM_THREADS": "1"}, {}),
    "default, LP_NUM_THREADS=0": ({"LP_NUM_THREADS": "0"}, {}),
    "standard (LIBERO's look)": ({}, {"quality": "standard"}),
    "default, collision boxes hidden": ({}, {"hide_collision": True}),
}


def prepare(args, out: Path) -> None:
    """One episode's frame states, the compiled model and LIBERO's reset fields, into `out`."""
    from pipeline.config import load_config
    from pipeline.policies.factory import make_policy
    from pipeline.rollout import run_episode
    from pipeline.sim import SimEnv
    from pipeline.sim.registry import tasks
    from pipeline.sim.state_render import reset_fields, save_model
    from pipeline.stage1.recorder import EpisodeRecorder
    from pipeline.stage1.video import frame_steps

    cfg = load_config("configs/smoke.yaml")
    task = tasks([args.suite])[args.task_index]
    with SimEnv(task) as env:
        policy = make_policy(cfg.stage1.policy)
        env.reset_to_init(0)
        env.settle(cfg.stage1.rollout.settle_steps)
        policy.reset(task, 1)
        rec = EpisodeRecorder(env)
        run_episode(env, policy, args.horizon, cfg.stage1.rollout.chunk_size, False, on_step=rec.on_step)
        states = rec.states_array()
        np.save(out / "states.npy", states[frame_steps(len(states) - 1, FPS)])
        save_model(env, out / "model.mjb")
        np.savez(out / "fields.npz", **reset_fields(env))
        policy.close()
    print(f"{task.task_id}: {len(np.load(out / 'states.npy'))} frames x {len(CAMERAS)} cameras at {SIZE} px", flush=True)


def child(folder: Path, name: str, opts: dict, reps: int) -> None:
    """Render the frames `reps` times (after one warm pass); print CPU ms per frame as JSON."""
    from pipeline.sim.state_render import StateRenderer
    from pipeline.stage1.video import write_videos

    quality = opts.get("quality", "fast")
    fields = dict(np.load(folder / "fields.npz"))
    states = np.load(folder / "states.npy")
    sr = StateRenderer(folder / "model.mjb")
    r = sr.renderer(SIZE, quality)
    r.cull = r.cull and opts.get("cull", True)
    if opts.get("hide_collision"):
        m = sr.model
        boxes = (m.geom_group == 0) & (m.geom_rgba[:, 3] > 0) & (m.geom_rgba[:, 3] < 1) & (
            (m.geom_contype != 0) | (m.geom_conaffinity != 0))
        m.geom_group[boxes] = 3
    frames = sr.render_states(states, CAMERAS, SIZE, quality, fields)  # warm
    c0 = time.process_time()
    for _ in range(reps):
        frames = sr.render_states(states, CAMERAS, SIZE, quality, fields)
    render_ms = (time.process_time() - c0) / (reps * len(states) * len(CAMERAS)) * 1e3
    c0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        write_videos(frames, list(range(len(states))), Path(tmp), FPS)
    encode_ms = (time.process_time() - c0) / (len(states) * len(CAMERAS)) * 1e3
    np.save(folder / f"frames-{name}.npy", np.stack([frames[c] for c in CAMERAS]))
    sr.close()
    print(json.dumps({"render_ms": render_ms, "encode_ms": encode_ms}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="libero_spatial")
    ap.add_argument("--task-index", type=int, default=0)
    ap.add_argument("--horizon", type=int, default=160)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=2, help="render passes per measurement")
    ap.add_argument("--child", nargs=3, metavar=("FOLDER", "NAME", "OPTIONS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(Path(args.child[0]), args.child[1], json.loads(args.child[2]), args.reps)

    folder = Path(tempfile.mkdtemp(prefix="render-cost-"))
    prepare(args, folder)
    runs: dict[str, list[dict]] = {name: [] for name in OPTIONS}
    keys = {name: f"o{i}" for i, name in enumerate(OPTIONS)}
    for _ in range(args.rounds):
        for name, (env_vars, opts) in OPTIONS.items():
            out = subprocess.run(
                [sys.executable, __file__, "--reps", str(args.reps), "--child", str(folder), keys[name], json.dumps(opts)],
                env={**os.environ, **env_vars}, capture_output=True, text=True, check=True)
            runs[name].append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(f"  {name:<34} render {runs[name][-1]['render_ms']:6.1f} ms", flush=True)
    base = np.load(folder / f"frames-{keys['default (fast, culled)']}.npy").astype(np.int16)
    ref = np.median([r["render_ms"] for r in runs["default (fast, culled)"]])
    print(f"CPU ms per frame (median of {args.rounds} rounds; 1 frame = 1 camera), pixel difference vs the default:")
    for name in OPTIONS:
        render = np.median([r["render_ms"] for r in runs[name]])
        encode = np.median([r["encode_ms"] for r in runs[name]])
        diff = np.abs(np.load(folder / f"frames-{keys[name]}.npy").astype(np.int16) - base)
        print(f"  {name:<34} render {render:6.1f} ms ({render / ref:4.2f}x)  encode {encode:4.1f} ms  "
              f"pixels: mean {diff.mean():5.2f}/255, {(diff.max(-1) > 16).mean() * 100:5.2f}% off by > 16", flush=True)
    print(f"(frames and states in {folder})")


if __name__ == "__main__":
    main()
