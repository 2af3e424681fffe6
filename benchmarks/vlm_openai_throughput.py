"""Benchmark: `openai` backend throughput at 1 vs. 8 requests in flight, and request preparation time.

Runs the real client against a real OpenAI-compatible server on loopback that answers every
request after a fixed delay (standing in for a GPU server's generation time), so the ratio
shows how well the client overlaps requests. Also times preparing one request (decode,
sample, resize, encode) from a 26 s, 20 fps, 256x256 MP4, in both video modes.

    .venv/bin/python benchmarks/vlm_openai_throughput.py [--delay 0.5] [--requests 16]

Target (issue 4): throughput at 8 in flight >= 6x throughput at 1.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.config import OpenAIBackendConfig, SamplingConfig  # noqa: E402
from pipeline.labelers.vlm.backends.base import VLMRequest  # noqa: E402
from pipeline.labelers.vlm.backends.openai_backend import OpenAIBackend  # noqa: E402
from pipeline.labelers.vlm.prompts import load_prompts  # noqa: E402
from tests.labelers.vlm.loopback_server import LoopbackServer  # noqa: E402

INSTRUCTION = "put the black bowl on the plate"


def synthetic_video(path: Path, seconds: float, fps: int = 20, size: int = 256) -> Path:
    """A textured scene with a moving block, so JPEG/H.264 sizes are realistic."""
    import av

    rng = np.random.default_rng(0)
    background = rng.integers(60, 200, (size, size, 3), dtype=np.uint8)
    with av.open(str(path), mode="w") as out:
        stream = out.add_stream("libx264", rate=Fraction(fps))
        stream.width = stream.height = size
        stream.pix_fmt = "yuv420p"
        for i in range(int(seconds * fps)):
            img = background.copy()
            x = int((size - 40) * (0.5 + 0.5 * np.sin(i / 15)))
            img[100:140, x : x + 40] = (200, 30, 30)
            out.mux(stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")))
        out.mux(stream.encode())
    return path


def throughput(base_url: str, video: Path, n: int, in_flight: int) -> float:
    cfg = OpenAIBackendConfig(base_url=base_url, model="slow", max_in_flight=in_flight, max_retries=0)
    backend = OpenAIBackend(cfg, SamplingConfig(fps=2.0), load_prompts("zh"))
    reqs = [VLMRequest(task="localize", video=video, instruction=INSTRUCTION, key=str(i)) for i in range(n)]
    t0 = time.perf_counter()
    results = backend.run(reqs)
    elapsed = time.perf_counter() - t0
    bad = [r.error for r in results if r.error]
    if bad:
        raise SystemExit(f"requests failed: {bad[:3]}")
    return n / elapsed


def prepare_time(video: Path, mode: str, repeats: int = 3) -> float:
    cfg = OpenAIBackendConfig(video_mode=mode, send_media_io_kwargs=True)
    backend = OpenAIBackend(cfg, SamplingConfig(fps=2.0), load_prompts("zh"))
    req = VLMRequest(task="localize", video=video, instruction=INSTRUCTION)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        backend.prepare(req)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--delay", type=float, default=0.5, help="server seconds per request")
    ap.add_argument("--requests", type=int, default=16)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        clip = synthetic_video(Path(tmp) / "clip_2s.mp4", 2.0)
        long = synthetic_video(Path(tmp) / "episode_26s.mp4", 26.0)
        with LoopbackServer(delay_s=args.delay, inspect=False) as srv:
            throughput(srv.base_url, clip, 2, 2)  # warm-up (imports, connections)
            one = throughput(srv.base_url, clip, args.requests, 1)
            eight = throughput(srv.base_url, clip, args.requests, 8)
        prep = {mode: prepare_time(long, mode) for mode in ("frames", "mp4")}
    ratio = eight / one
    print(f"server delay {args.delay:.2f} s/request, {args.requests} requests of a 2 s clip")
    print(f"  1 in flight : {one:6.2f} req/s")
    print(f"  8 in flight : {eight:6.2f} req/s")
    print(f"  ratio       : {ratio:6.2f}x  (target >= 6x: {'PASS' if ratio >= 6 else 'FAIL'})")
    print("prepare one request from a 26 s, 20 fps, 256x256 MP4 (52 frames at 2 fps, 224x224):")
    for mode, t in prep.items():
        print(f"  {mode:6s}: {t * 1000:7.1f} ms")
    print(f"  mp4 / frames: {prep['mp4'] / prep['frames']:.2f}x")


if __name__ == "__main__":
    main()
