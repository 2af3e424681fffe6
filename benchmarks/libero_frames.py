"""Our frames beside LIBERO's own, one scene per suite: a picture and the pixel differences.

    .venv/bin/python benchmarks/libero_frames.py [--size 256] [--out benchmarks/results]

For each scene (the same ones as tests/sim/test_libero_frames.py) a mid-episode state is
restored in plain LIBERO (`OffScreenRenderEnv`, `np.random.seed(0)`, `reset()`,
`set_init_state`) and rendered by robosuite's offscreen context (flipped right side up), and
by us at standard quality, at fast quality and with the renderer before version 2
(collision geometry drawn). Writes `libero_frames.png` (a row per scene: LIBERO | ours |
renderer v1, agentview then wrist) and `libero_frames.json` (mean / max absolute pixel
difference against LIBERO's frame, share of pixels that differ, per camera and option).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from tests.sim.test_libero_frames import SCENES, mid_episode_state  # noqa: E402  (one list of scenes)

CAMERAS = ("agentview", "robot0_eye_in_hand")


def measure(suite: str, name: str, size: int) -> tuple[dict, list[np.ndarray]]:
    from pipeline.sim import SimEnv, get_task
    from pipeline.sim.libero_setup import ensure_libero_ready

    ensure_libero_ready()  # LIBERO's config first, or its import asks for a folder on stdin
    from libero.libero.envs import OffScreenRenderEnv

    task = get_task(suite, name)
    with SimEnv(task) as env:
        state = mid_episode_state(env)
        lib = OffScreenRenderEnv(bddl_file_name=str(task.bddl_path), camera_heights=size, camera_widths=size)
        try:
            np.random.seed(0)
            lib.reset()
            obs = lib.set_init_state(state)
            theirs = {c: obs[f"{c}_image"][::-1] for c in CAMERAS}
        finally:
            lib.close()
        env.set_state(state)
        ours = {c: env.render(c, size, "standard") for c in CAMERAS}
        fast = {c: env.render(c, size, "fast") for c in CAMERAS}
        from pipeline.sim.render import FrameRenderer

        r = FrameRenderer(env.env.sim.model._model, size, "standard")
        r.option.geomgroup[0] = 1  # the renderer before version 2
        try:
            old = {c: r.render(env.env.sim.data._data, c) for c in CAMERAS}
        finally:
            r.close()
    row, stats = [], {}
    for c in CAMERAS:
        row += [theirs[c], ours[c], old[c]]
        for label, img in (("standard", ours[c]), ("fast", fast[c]), ("v1 standard", old[c])):
            d = np.abs(img.astype(int) - theirs[c].astype(int))
            stats[f"{c} {label}"] = {"mean": round(float(d.mean()), 3), "max": int(d.max()),
                                     "pixels_differing": round(float((d.max(-1) > 0).mean()), 4)}
    return stats, row


def main() -> None:
    from PIL import Image, ImageDraw

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    results, rows = {}, []
    for suite, name in SCENES:
        stats, row = measure(suite, name, args.size)
        results[f"{suite}/{name}"] = stats
        rows.append(np.concatenate(row, axis=1))
        print(f"{suite}/{name[:50]}: " + "; ".join(f"{k} mean {v['mean']} max {v['max']}" for k, v in stats.items()),
              flush=True)
    grid = Image.fromarray(np.concatenate(rows, axis=0))
    draw = ImageDraw.Draw(grid)
    for j, label in enumerate(["LIBERO agentview", "ours", "v1 (before)", "LIBERO wrist", "ours", "v1 (before)"]):
        draw.text((j * args.size + 4, 2), label, fill=(255, 255, 0))
    for i, (suite, _) in enumerate(SCENES):
        draw.text((4, i * args.size + args.size - 14), suite, fill=(255, 255, 0))
    grid.save(args.out / "libero_frames.png")
    (args.out / "libero_frames.json").write_text(json.dumps(results, indent=1))
    print(f"wrote {args.out / 'libero_frames.png'} and {args.out / 'libero_frames.json'}")


if __name__ == "__main__":
    main()
