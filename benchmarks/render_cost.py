"""Cost of one stage-1 video frame per render option, and how far each is from LIBERO's own frame.

    .venv/bin/python benchmarks/render_cost.py [--suite libero_spatial] [--task-index 0] [--rounds 3]
    .venv/bin/python benchmarks/render_cost.py --from FOLDER   # a prepared folder (e.g. on a GPU machine)

One episode of the smoke config's policy (160 steps, no early stop) gives the states of a
4-fps video; LIBERO's own `OffScreenRenderEnv` renders each of those states at 256 px (the
reference, `libero.npz`). Each option then renders the same frames of both cameras at 256 px
in a fresh process, as stage 1's render process does (pipeline/sim/state_render.py, from the
saved model, or from `scene.xml` + `assets/` where no MJB is there), warm (renderer built, one
pass first), and reports process CPU time per frame (`time.process_time`: every thread,
llvmpipe's included), wall time per frame (what counts on a GPU, where the CPU waits), the
H.264 encode per frame, and the mean / max pixel difference against LIBERO's frame. Rounds
alternate the options so drifting load spreads evenly.

Options: standard (LIBERO's frame: the only quality for policies and training data), fast
(no MSAA, no reflections, geoms outside the view culled: the stage-1 video default), fast not
culled, LP_NUM_THREADS=1 (Mesa's llvmpipe threads; read once per process), and the renderer
before version 2 at both qualities (robosuite's collision geometry drawn: geom group 0).
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
    "standard (LIBERO's frame)": ({}, {"quality": "standard"}),
    "fast (culled, video default)": ({}, {}),
    "fast, not culled": ({}, {"cull": False}),
    "fast, LP_NUM_THREADS=1": ({"LP_NUM_THREADS": "1"}, {}),
    "v1 standard (collision drawn)": ({}, {"quality": "standard", "collision": True}),
    "v1 fast (collision drawn)": ({}, {"collision": True}),
}
REFERENCE = "standard (LIBERO's frame)"


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
    np.savez_compressed(out / "libero.npz", **libero_frames(task, np.load(out / "states.npy")))
    print(f"{task.task_id}: {len(np.load(out / 'states.npy'))} frames x {len(CAMERAS)} cameras at {SIZE} px", flush=True)


def libero_frames(task, states: np.ndarray) -> dict[str, np.ndarray]:
    """LIBERO's own frames of `states`: `OffScreenRenderEnv` restored as the card says, then
    robosuite's `sim.render` (its observation call) per state, flipped right side up."""
    from libero.libero.envs import OffScreenRenderEnv

    env = OffScreenRenderEnv(bddl_file_name=str(task.bddl_path), camera_heights=SIZE, camera_widths=SIZE)
    try:
        np.random.seed(0)
        env.reset()
        out: dict[str, list] = {c: [] for c in CAMERAS}
        for state in states:
            env.set_init_state(state)
            for c in CAMERAS:
                out[c].append(env.env.sim.render(camera_name=c, width=SIZE, height=SIZE)[::-1])
        return {c: np.asarray(v) for c, v in out.items()}
    finally:
        env.close()


def _state_renderer(folder: Path):
    """The stage-1 render process's renderer, from the MJB or, where there is none, the XML."""
    from pipeline.sim.state_render import StateRenderer

    mjb = folder / "model.mjb"
    return StateRenderer(mjb if mjb.is_file() else folder / "scene.xml")


def child(folder: Path, name: str, opts: dict, reps: int) -> None:
    """Render the frames `reps` times (after one warm pass); print ms per frame as JSON."""
    from pipeline.stage1.video import write_videos

    quality = opts.get("quality", "fast")
    fields = dict(np.load(folder / "fields.npz"))
    states = np.load(folder / "states.npy")
    sr = _state_renderer(folder)
    r = sr.renderer(SIZE, quality)
    r.cull = r.cull and opts.get("cull", True)
    if opts.get("collision"):  # the renderer before version 2
        r.option.geomgroup[0] = 1
    frames = sr.render_states(states, CAMERAS, SIZE, quality, fields)  # warm
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in range(reps):
        frames = sr.render_states(states, CAMERAS, SIZE, quality, fields)
    n = reps * len(states) * len(CAMERAS)
    render_ms, wall_ms = (time.process_time() - c0) / n * 1e3, (time.perf_counter() - w0) / n * 1e3
    c0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        write_videos(frames, list(range(len(states))), Path(tmp), FPS)
    encode_ms = (time.process_time() - c0) / (len(states) * len(CAMERAS)) * 1e3
    np.save(folder / f"frames-{name}.npy", np.stack([frames[c] for c in CAMERAS]))
    sr.close()
    print(json.dumps({"render_ms": render_ms, "wall_ms": wall_ms, "encode_ms": encode_ms}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="libero_spatial")
    ap.add_argument("--task-index", type=int, default=0)
    ap.add_argument("--horizon", type=int, default=160)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=2, help="render passes per measurement")
    ap.add_argument("--from", dest="folder", type=Path, help="a prepared folder (states, fields, model, libero.npz)")
    ap.add_argument("--json", type=Path, help="also write the table as JSON here")
    ap.add_argument("--child", nargs=3, metavar=("FOLDER", "NAME", "OPTIONS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(Path(args.child[0]), args.child[1], json.loads(args.child[2]), args.reps)

    folder = args.folder or Path(tempfile.mkdtemp(prefix="render-cost-"))
    if args.folder is None:
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
    lib = np.load(folder / "libero.npz")
    base = np.stack([lib[c] for c in CAMERAS]).astype(np.int16)
    ref = np.median([r["render_ms"] for r in runs[REFERENCE]])
    print(f"ms per frame (median of {args.rounds} rounds; 1 frame = 1 camera, {SIZE} px), pixels vs LIBERO's own frame:")
    table = []
    for name in OPTIONS:
        row = {k: float(np.median([r[k] for r in runs[name]])) for k in ("render_ms", "wall_ms", "encode_ms")}
        diff = np.abs(np.load(folder / f"frames-{keys[name]}.npy").astype(np.int16) - base)
        row.update(option=name, mean_diff=float(diff.mean()), max_diff=int(diff.max()),
                   off16_pct=float((diff.max(-1) > 16).mean() * 100))
        table.append(row)
        print(f"  {name:<32} CPU {row['render_ms']:6.1f} ms ({row['render_ms'] / ref:4.2f}x)  wall {row['wall_ms']:6.1f} ms"
              f"  encode {row['encode_ms']:4.1f} ms  pixels: mean {row['mean_diff']:5.2f}/255, max {row['max_diff']:3d}, "
              f"{row['off16_pct']:5.2f}% off by > 16", flush=True)
    if args.json:
        args.json.write_text(json.dumps(table, indent=1))
    print(f"(frames and states in {folder})")


if __name__ == "__main__":
    main()
