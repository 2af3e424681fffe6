"""Tiny real inputs for the VLM tests: MP4s whose frames say which index they are."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pyarrow as pa

from pipeline.rendered import stamped
from pipeline.records import FRAME_SCHEMA


def frame_value(i: int, n: int) -> int:
    """Gray level of frame i of n: distinct enough to survive H.264 and JPEG."""
    return int(round(16 + 220 * i / max(1, n - 1)))


def write_video(path: str | Path, n_frames: int, fps: int = 20, size: tuple[int, int] = (64, 48)) -> Path:
    """An H.264 MP4 of `n_frames` flat gray frames at `fps`; frame i has `frame_value(i)`."""
    import av

    path = Path(path)
    w, h = size
    with av.open(str(path), mode="w") as out:
        stream = out.add_stream("libx264", rate=Fraction(fps))
        stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
        for i in range(n_frames):
            img = np.full((h, w, 3), frame_value(i, n_frames), dtype=np.uint8)
            out.mux(stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")))
        out.mux(stream.encode())
    return path


def frames_table(n_frames: int, video_fps: int = 20, control_hz: int = 20) -> pa.Table:
    """Stage 1's frame<->step table for a video rendered every control_hz/video_fps steps."""
    every = control_hz // video_fps
    steps = [i * every for i in range(n_frames)]
    return pa.table(
        {"frame": list(range(n_frames)), "step": steps, "time_s": [s / control_hz for s in steps]}, schema=stamped(FRAME_SCHEMA)
    )
