"""Does the same footage give the same MP4 bytes? x264's defaults against `pipeline.h264`'s
settings, side by side in one run, with file size and picture quality.

    nice -n 10 .venv/bin/python benchmarks/h264_repeatability.py [--run RUN] [--episodes 2] [--repeats 60]

Renders both cameras of the first `--episodes` failed stage-1 episodes of RUN from their
logged states (20 Hz, LeRobot export's rendering, 64 / 96 / 256 px; RUN is only read), and
the random-motion clip of tests/release/test_h264.py at 64 / 96 px (and its 64 px wrist frames
with every pixel doubled, cropped to 96 px: the footage of the first one-thread probes), then:

- repeatability: encodes 24-frame windows of each clip `--repeats` times in this process,
  between encodes allocating and freeing buffers of random sizes (what a long export does),
  and counts the different files; encodes them allowed on 1 core and on all (x264 sizes its
  default thread pool from the cores, as on machines of different sizes); and with the
  encoder's thread count forced to 1-4 (which `repeatable` would otherwise pin to 1);
- size and quality: every whole clip at 256 px, the file size and PSNR of the decoded frames
  against the rendered ones, for the defaults and for mb-tree off at several crf values.

Settings: "x264 default" is what the LeRobot export used before (crf 20, GOP 2, threads
auto, mb-tree on; stage 1: crf 23, x264's GOP, one thread); "repeatable crf N" is
`pipeline.h264.repeatable` (one thread, mb-tree off); "one thread, mb-tree on" tells the two
causes apart.
"""

from __future__ import annotations

import argparse
import io
import os
import random
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

CAMERAS = ["agentview", "robot0_eye_in_hand"]
WINDOWS = (60, 160, 260)  # 24-step windows for the repeatability counts


def clips(run: Path, episodes: int, sizes: tuple[int, ...]) -> list[dict[int, dict[str, np.ndarray]]]:
    """Per episode: size -> camera -> rendered frames (standard quality). 256 px: every control
    step; smaller sizes: 24-step windows starting at WINDOWS (the arm is moving there)."""
    from pipeline.config import load_config
    from pipeline.layout import EpisodeFiles, RunLayout
    from pipeline.records import read_episodes
    from pipeline.sim import SimEnv, get_task

    cfg = load_config(run / "config.resolved.yaml")
    stage1 = RunLayout.of(cfg).stage1
    failed = [e for e in read_episodes(stage1.manifest) if not e.success][:episodes]
    out = []
    for e in failed:
        states = np.load(EpisodeFiles(stage1.episode(e).dir).states)
        window = np.concatenate([states[w : w + 24] for w in WINDOWS])
        with SimEnv(get_task(e.suite, e.task)) as env:
            out.append({size: env.render_states(states if size == 256 else window, CAMERAS, size)
                        for size in sizes})
        print(f"rendered {e.key}: {len(states)} states", flush=True)
    return out


def random_motion(sizes: tuple[int, ...]) -> dict[int, dict[str, np.ndarray]]:
    """The clip of tests/release/test_h264.py: libero_spatial task 0 from init state 0, 72
    steps of seeded random arm motion (three 24-step windows, like the run's clips)."""
    from pipeline.sim import SimEnv, tasks

    rng = np.random.default_rng(0)
    with SimEnv(tasks(["libero_spatial"])[0]) as env:
        env.reset_to_init(0)
        states = []
        for i in range(24 * len(WINDOWS)):
            if i % 24 == 0:
                env.reset_to_init(0)
            env.step(np.r_[rng.normal(0, 0.5, 6), 1.0 if i % 24 > 12 else -1.0])
            states.append(env.get_state())
        return {size: env.render_states(np.asarray(states), CAMERAS, size) for size in sizes if size != 256}


def encode(frames: np.ndarray, setting: str, crf: int, threads: int | None = None, fps: int = 20) -> bytes:
    import av

    from pipeline.h264 import repeatable

    buf = io.BytesIO()
    with av.open(buf, "w", format="mp4") as box:
        stream = box.add_stream("libx264", rate=fps)
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "yuv420p"
        gop = {"g": "2"} if fps == 20 else {}  # the LeRobot export's short GOP; stage 1 keeps x264's
        if setting in ("default", "one thread"):
            stream.options = {"crf": str(crf), **gop}
            if setting == "one thread":  # mb-tree still on
                stream.codec_context.thread_count = 1
        else:
            repeatable(stream, crf, **gop)
        if threads is not None:
            stream.codec_context.thread_count = threads
        for f in frames:
            box.mux(stream.encode(av.VideoFrame.from_ndarray(f, format="rgb24")))
        box.mux(stream.encode())
    return buf.getvalue()


def psnr(data: bytes, frames: np.ndarray) -> float:
    import av

    with av.open(io.BytesIO(data)) as c:
        dec = np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)])
    mse = float(((dec.astype(np.float64) - frames) ** 2).mean())
    return 10 * np.log10(255**2 / mse)


def distinct_files(frames: np.ndarray, setting: str, crf: int, repeats: int) -> int:
    rng, junk, seen = random.Random(0), [], Counter()
    for _ in range(repeats):
        junk.append(bytearray(rng.randrange(1, 1 << 16)))
        if len(junk) > 64:
            junk.pop(rng.randrange(len(junk)))
        seen[encode(frames, setting, crf)] += 1
    return len(seen)


def per_core_count(frames: np.ndarray, setting: str, crf: int) -> int:
    """Different files when this process may run on 1 core and on all of its cores (x264
    sizes its default thread pool from them, as on machines of different sizes)."""
    cores = os.sched_getaffinity(0)
    files = set()
    for allowed in ({min(cores)}, cores):
        os.sched_setaffinity(0, allowed)
        try:
            files.add(encode(frames, setting, crf))
        finally:
            os.sched_setaffinity(0, cores)
    return len(files)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=Path("/work/runs/final100_s5"))
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=60)
    args = ap.parse_args()
    sizes = (64, 96, 256)
    data = clips(args.run, args.episodes, sizes)
    motion = random_motion(sizes)
    settings = [("x264 default crf 20", "default", 20), ("repeatable crf 22", "repeatable", 22)]

    cores = len(os.sched_getaffinity(0))
    print(f"\nrepeatability: different files from the same 24 frames ({args.repeats} encodes in one process;"
          f" 1 vs {cores} cores; forced 1-4 encoder threads)")
    print(f"{'setting':22} {'clip':32} {'size':>5} {'same process':>13} {'cores':>6} {'threads':>8}")

    def row(label: str, size: int, clip: np.ndarray) -> None:
        for name, setting, crf in settings:
            n = distinct_files(clip, setting, crf, args.repeats)
            c = per_core_count(clip, setting, crf)
            t = len({encode(clip, setting, crf, threads) for threads in (1, 2, 3, 4)})
            print(f"{name:22} {label:32} {size:5} {n:13} {c:6} {t:8}", flush=True)

    for i, ep in enumerate(data):
        for size in sizes:
            for cam, frames in ep[size].items():
                for w, start in enumerate(WINDOWS):
                    row(f"ep {i} {cam} @{start}", size,
                        frames[start : start + 24] if size == 256 else frames[24 * w : 24 * w + 24])
    for size, cams in motion.items():
        for cam, frames in cams.items():
            for w in range(len(WINDOWS)):
                row(f"random motion {cam} #{w}", size, frames[24 * w : 24 * w + 24])
    # the clip first seen to differ with one thread: 64 px wrist renders, each pixel doubled,
    # cropped to 96 px
    settings.insert(1, ("one thread, mb-tree on", "one thread", 20))
    wrist = motion[64]["robot0_eye_in_hand"]
    for w in range(len(WINDOWS)):
        big = np.repeat(np.repeat(wrist[24 * w : 24 * w + 24], 2, axis=1), 2, axis=2)[:, :96, :96]
        row(f"random motion wrist 2x crop #{w}", 96, np.ascontiguousarray(big))

    print("\nsize and quality: whole clips at 256 px (kB, PSNR dB of the decoded frames)")
    rows = [("x264 default crf 20", "default", 20)] + [(f"repeatable crf {c}", "repeatable", c) for c in (20, 21, 22, 23)]
    for name, setting, crf in rows:
        cells, total = [], 0
        for i, ep in enumerate(data):
            for cam, frames in ep[256].items():
                b = encode(frames, setting, crf)
                total += len(b)
                cells.append(f"{len(b) / 1e3:6.0f} kB {psnr(b, frames):5.2f} dB")
        print(f"{name:22} " + " | ".join(cells) + f"   total {total / 1e3:.0f} kB")

    print("\nstage 1's videos: every 5th frame at 4 fps, x264's own GOP (kB, PSNR dB)")
    for name, setting, crf in [("x264 default crf 23", "default", 23)] + [
            (f"repeatable crf {c}", "repeatable", c) for c in (24, 25)]:
        cells, total = [], 0
        for ep in data:
            for frames in ep[256].values():
                b = encode(frames[::5], setting, crf, fps=4)
                total += len(b)
                cells.append(f"{len(b) / 1e3:6.0f} kB {psnr(b, frames[::5]):5.2f} dB")
        print(f"{name:22} " + " | ".join(cells) + f"   total {total / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
