"""Videos of an episode, rendered from its logged states after the physics.

Inputs: a `SimEnv` of the episode's task, the episode's `states.npy` array (row t = state
before action t, last row = final state), cameras, fps (a divisor of the 20 Hz control
rate) and resolution. Outputs: `video_<camera>.mp4` (H.264, yuv420p, `fps`) per camera and
`frames.parquet` (`FRAME_SCHEMA`, stamped with the renderer version: pipeline/rendered.py),
all written atomically, the frame table last (it marks the videos complete).

Invariants: frame i shows state row `i * 20 / fps`; the final state is always the last
frame (its step is `steps`, possibly closer than one frame interval to the previous one);
every camera's video has exactly the rows of `frames.parquet`. Rendering sets the state
and runs `forward` only, so it never changes what the rollout did.
"""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic import atomic_path, write_with
from pipeline.h264 import repeatable
from pipeline.layout import EpisodeFiles, video_name
from pipeline.records import FRAME_SCHEMA
from pipeline.rendered import stamped
from pipeline.sim import CONTROL_HZ, SimEnv


def frame_steps(steps: int, fps: int, control_hz: int = CONTROL_HZ) -> list[int]:
    """Simulator steps shown by the frames of an episode of `steps` policy steps."""
    if fps <= 0 or control_hz % fps:
        raise ValueError(f"fps {fps} must divide the control rate {control_hz}")
    stride = control_hz // fps
    out = list(range(0, steps + 1, stride))
    if out[-1] != steps:
        out.append(steps)  # the final state is always shown
    return out


def frame_table(steps: list[int], control_hz: int = CONTROL_HZ) -> pa.Table:
    return pa.Table.from_arrays(
        [
            pa.array(np.arange(len(steps), dtype=np.int32)),
            pa.array(np.asarray(steps, dtype=np.int32)),
            pa.array(np.asarray(steps, dtype=np.float64) / control_hz),
        ],
        schema=stamped(FRAME_SCHEMA),
    )


class Mp4Writer:
    """H.264/yuv420p MP4 through PyAV; the same frames give the same bytes (`pipeline.h264`)."""

    def __init__(self, path: Path, fps: int, size: int):
        self.container = av.open(str(path), mode="w")
        self.stream = self.container.add_stream("libx264", rate=fps)
        self.stream.width = self.stream.height = size
        self.stream.pix_fmt = "yuv420p"
        repeatable(self.stream, crf=24)  # without mb-tree ~ x264's default crf 23 (h264_repeatability.py)

    def add(self, frame: np.ndarray) -> None:
        for packet in self.stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
            self.container.mux(packet)

    def close(self) -> None:
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()


def write_videos(
    frames: dict[str, np.ndarray | list[np.ndarray]], steps: list[int], folder: Path, fps: int
) -> dict[str, str]:
    """Encode already-rendered frames (camera -> list of HxWx3) plus the frame table."""
    folder = Path(folder)
    videos = {}
    for camera, images in frames.items():
        if len(images) != len(steps):
            raise ValueError(f"{camera}: {len(images)} frames for {len(steps)} steps")
        name = video_name(camera)
        with atomic_path(folder / name) as tmp:
            w = Mp4Writer(tmp, fps, images[0].shape[0])
            for img in images:
                w.add(img)
            w.close()
        videos[camera] = name
    table = frame_table(steps)
    write_with(EpisodeFiles(folder).frames, lambda p: pq.write_table(table, p))
    return videos


def render_videos(
    env: SimEnv, states: np.ndarray, folder: str | Path, cameras: list[str], fps: int, size: int,
    quality: str = "standard",
) -> dict[str, str]:
    """Render `cameras` from logged states at `fps`; return camera -> file name."""
    steps = frame_steps(len(states) - 1, fps)
    frames = env.render_states(states[steps], cameras, size, quality)
    return write_videos(frames, steps, Path(folder), fps)


def read_video(path: str | Path) -> list[np.ndarray]:
    """Decode an MP4 into RGB frames (for tests and tools)."""
    with av.open(str(path)) as c:
        return [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
