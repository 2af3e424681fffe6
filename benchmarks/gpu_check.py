"""What a GPU machine changes: frame cost of the renderer, and the transformers VLM backend on CUDA.

    python benchmarks/gpu_check.py export FOLDER   # here: states, fields, scene.xml + assets/ for `render`
    python benchmarks/gpu_check.py render FOLDER   # there: a folder from `export`
    python benchmarks/gpu_check.py vlm [--family qwen3_5]

Meant for a lent GPU machine whose image has CUDA torch and transformers but no LIBERO or
robosuite (and no network): the render check needs only mujoco, numpy and the project's
renderer module, loaded from its file so that `pipeline.sim`'s package import (LIBERO) is not
needed; the scene comes as the MJCF robosuite compiles plus its asset files. It renders
the folder's states at 256 px, both cameras, at standard and fast quality and with the
renderer before version 2, and prints wall and CPU ms per frame (EGL, `MUJOCO_GL=egl`) and
how far each frame is from LIBERO's own (`libero.npz`, rendered by `export` where LIBERO runs).

The VLM check builds a tiny random Qwen-VL checkpoint offline (tests/labelers/vlm/tiny_qwen.py),
writes a 26 s 4-fps 128 px video, and runs `TransformersBackend` on `cuda` in bf16 through its
real start-up (torch_compat's torchvision import order on a CUDA build), processor and
`generate`, twice (cold and warm).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CAMERAS = ["agentview", "robot0_eye_in_hand"]


def render(folder: Path, reps: int) -> dict:
    import mujoco
    import numpy as np

    spec = importlib.util.spec_from_file_location("render", REPO / "pipeline/sim/render.py")
    render_mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(render_mod)
    model = mujoco.MjModel.from_xml_path(str(folder / "scene.xml"))
    data = mujoco.MjData(model)
    for name, value in np.load(folder / "fields.npz").items():
        getattr(model, name)[:] = value
    states = np.load(folder / "states.npy")
    # LIBERO's own frames of these states, rendered by `export` on the machine that has LIBERO
    lib = np.load(folder / "libero.npz") if (folder / "libero.npz").exists() else None
    base = np.stack([lib[c] for c in CAMERAS], axis=1).astype(np.int16) if lib is not None else None
    out = {"gl_vendor": None, "frames": len(states) * len(CAMERAS)}
    for name, quality, collision in (("standard", "standard", False), ("fast", "fast", False),
                                     ("v1 standard (collision drawn)", "standard", True)):
        r = render_mod.FrameRenderer(model, 256, quality)
        if collision:
            r.option.geomgroup[0] = 1
        if out["gl_vendor"] is None:
            from OpenGL import GL

            out["gl_vendor"] = " / ".join(GL.glGetString(x).decode() for x in (GL.GL_VENDOR, GL.GL_RENDERER))

        def one_pass():
            frames = []
            for s in states:
                data.time, data.qpos[:], data.qvel[:] = s[0], s[1 : 1 + model.nq], s[1 + model.nq :]
                mujoco.mj_forward(model, data)
                frames += [r.render(data, c) for c in CAMERAS]
            return frames

        one_pass()  # warm
        c0, w0 = time.process_time(), time.perf_counter()
        for _ in range(reps):
            frames = one_pass()
        n = reps * len(states) * len(CAMERAS)
        out[name] = {"wall_ms": (time.perf_counter() - w0) / n * 1e3, "cpu_ms": (time.process_time() - c0) / n * 1e3,
                     "mean_pixel": float(np.mean(frames))}
        if base is not None:
            diff = np.abs(np.asarray(frames, np.int16).reshape(base.shape) - base)
            out[name] |= {"vs_libero_mean": float(diff.mean()), "vs_libero_share_over_16": float((diff.max(-1) > 16).mean())}
        r.close()
    # the physics of those states alone (mj_forward per frame), to show what the frame costs beside it
    w0 = time.perf_counter()
    for s in states:
        data.qpos[:] = s[1 : 1 + model.nq]
        mujoco.mj_forward(model, data)
    out["mj_forward_ms"] = (time.perf_counter() - w0) / len(states) * 1e3
    return out


def export(folder: Path) -> dict:
    """Write what `render` needs, on a machine with LIBERO: `render_cost.py`'s states and
    reset fields of its episode (libero_spatial task 0), and the scene as robosuite compiles
    it (`scene.xml`) with every file it names copied into `assets/` (the compiled MJB holds
    the textures unpacked, 284 MB, over what a device call may carry; `tar cJf` the folder:
    about 23 MB)."""
    import re
    import shutil
    from argparse import Namespace

    sys.path.insert(0, str(REPO / "benchmarks"))
    import render_cost

    from pipeline.sim import SimEnv
    from pipeline.sim.registry import tasks

    (folder / "assets").mkdir(parents=True, exist_ok=True)
    render_cost.prepare(Namespace(suite="libero_spatial", task_index=0, horizon=160), folder)
    (folder / "model.mjb").unlink()  # the XML below replaces it
    with SimEnv(tasks(["libero_spatial"])[0]) as env:
        xml = env.env.sim.model.get_xml()
    names: dict[str, str] = {}
    for path in sorted(set(re.findall(r'file="([^"]+)"', xml))):
        name, k = Path(path).name, 0
        while name in names.values():  # two meshes of one name from different folders
            k += 1
            name = f"{k}_{Path(path).name}"
        names[path] = name
        shutil.copy(path, folder / "assets" / name)
        xml = xml.replace(f'file="{path}"', f'file="assets/{name}"')
    (folder / "scene.xml").write_text(re.sub(r'(meshdir|texturedir)="[^"]*"', "", xml))
    return {"folder": str(folder), "assets": len(names)}


def vlm(family: str, device: str = "cuda") -> dict:
    import av
    import numpy as np

    from pipeline.labelers.vlm.torch_compat import ensure_torchvision

    ensure_torchvision()
    import torch
    import torchvision
    import transformers

    from pipeline.config import SamplingConfig, TransformersBackendConfig
    from pipeline.labelers.vlm.backends.transformers_backend import TransformersBackend
    from pipeline.labelers.vlm.prompts import load_prompts
    from tests.labelers.vlm.tiny_qwen import build_tiny_qwen

    tmp = Path(tempfile.mkdtemp())
    ckpt = build_tiny_qwen(tmp / family, family)
    video = tmp / "video.mp4"
    with av.open(str(video), "w") as c:
        s = c.add_stream("libx264", rate=4)
        s.width = s.height = 128
        s.pix_fmt = "yuv420p"
        rng = np.random.default_rng(0)
        for _ in range(104):
            for p in s.encode(av.VideoFrame.from_ndarray(rng.integers(0, 255, (128, 128, 3), dtype=np.uint8), "rgb24")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    cfg = TransformersBackendConfig(model_path=ckpt, max_new_tokens=32, device=device, dtype="bfloat16")
    t0 = time.perf_counter()
    backend = TransformersBackend(cfg, SamplingConfig(fps=2.0), load_prompts("en"))
    load_s = time.perf_counter() - t0
    runs = []
    for _ in range(2):
        t0 = time.perf_counter()
        result = backend.localize(video, "put the black bowl on the plate", None)
        runs.append(time.perf_counter() - t0)
    return {"torch": torch.__version__, "torchvision": torchvision.__version__, "transformers": transformers.__version__,
            "device": str(next(backend.model.parameters()).device), "dtype": str(next(backend.model.parameters()).dtype),
            "gpu": torch.cuda.get_device_name(0) if device == "cuda" else None, "load_s": load_s, "localize_s": runs, "error": result.error,
            "finish_reason": result.finish_reason, "completion_tokens": result.completion_tokens,
            "frames_sent": len(result.video.frames_indices)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["export", "render", "vlm"])
    ap.add_argument("folder", nargs="?", type=Path)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--family", default="qwen3_5")
    ap.add_argument("--device", default="cuda")
    args = ap.parse_args()
    if args.what in ("export", "render") and args.folder is None:
        raise SystemExit(f"gpu_check.py {args.what}: give the FOLDER")
    out = (export(args.folder) if args.what == "export" else render(args.folder, args.reps) if args.what == "render"
           else vlm(args.family, args.device))
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
