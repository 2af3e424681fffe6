"""Turn a rollout MP4 into the frames a VLM sees, with their true indices and times.

Input: an MP4 (stage 1's `video_<camera>.mp4`), a `SamplingConfig`, optionally stage 1's
frame<->step table. Output: a `SampledVideo` (uint8 frames N x H x W x 3, the frame indices
they came from, the source fps) and its encodings for the wire: a JPEG-frame-list data URL
(`data:video/jpeg;base64,<jpg1>,<jpg2>,...`) or an MP4 data URL.

Invariants:
- Time is frame_index / source_fps, where source_fps is the file's true rate (checked
  against the frames table when given). Every consumer gets the indices AND the source fps,
  never a bare frame list (a Qwen processor without them assumes 24 fps).
- Frames are evenly spaced: stride = round(source_fps / sampling.fps), raised until at most
  `max_frames` frames remain, so the effective rate is source_fps / stride (2 fps on a 20 Hz
  video: stride 10). Even spacing keeps Qwen2.5-VL's time position ids regular.
- Frames are downscaled (never upscaled) to at most `max_pixels`, keeping aspect, even sides.
- Decoding is PyAV only (transformers' own path needs torchcodec, which fails on CPU torch).
"""

from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pyarrow as pa

from pipeline.config import SamplingConfig
from pipeline.errors import EpisodeError
from pipeline.labelers.vlm.backends.base import VideoSent

FPS_TOLERANCE = 0.01  # relative disagreement allowed between container and frames table


@dataclass
class SampledVideo:
    path: str
    frames: np.ndarray  # (N, H, W, 3) uint8, already resized (and stamped, if asked)
    frames_indices: list[int]
    source_fps: float
    total_frames: int
    stride: int
    timestamp_overlay: bool

    @property
    def duration_s(self) -> float:
        return self.total_frames / self.source_fps

    @property
    def sample_fps(self) -> float:
        return self.source_fps / self.stride

    @property
    def timestamps_s(self) -> list[float]:
        return [i / self.source_fps for i in self.frames_indices]

    def describe(self, mode: str) -> VideoSent:
        n, h, w = self.frames.shape[:3]
        return VideoSent(
            path=self.path,
            source_fps=self.source_fps,
            total_frames=self.total_frames,
            duration_s=self.duration_s,
            sample_fps=self.sample_fps,
            frames_indices=list(self.frames_indices),
            width=w,
            height=h,
            mode=mode,
            timestamp_overlay=self.timestamp_overlay,
        )


def plan_indices(total_frames: int, source_fps: float, fps: float, max_frames: int) -> tuple[list[int], int]:
    """Evenly spaced frame indices (and the stride) for a target rate and a frame cap."""
    stride = max(1, round(source_fps / fps))
    stride = max(stride, math.ceil(total_frames / max_frames))
    return list(range(0, total_frames, stride)), stride


def target_size(width: int, height: int, max_pixels: int) -> tuple[int, int]:
    scale = min(1.0, math.sqrt(max_pixels / (width * height)))
    return max(2, int(width * scale) // 2 * 2), max(2, int(height * scale) // 2 * 2)


def _table_fps(table: pa.Table, path: Path, total_frames: int) -> float:
    frames = table.column("frame").to_numpy()
    times = table.column("time_s").to_numpy()
    if len(frames) != total_frames or not np.array_equal(frames, np.arange(total_frames)):
        raise EpisodeError(
            "video_table_mismatch", f"{path}: video has {total_frames} frames, frames table lists {len(frames)}"
        )
    if total_frames < 2:
        raise EpisodeError("video_too_short", f"{path}: {total_frames} frame(s)")
    return round(float(1.0 / np.median(np.diff(times))), 6)  # 1/0.05 -> 20.0, not 19.999...


def draw_timestamp(frame: np.ndarray, seconds: float) -> np.ndarray:
    """Write `12.5s` into the top-left corner on a dark box (helps models tell time)."""
    from PIL import Image, ImageDraw, ImageFont

    img = Image.fromarray(frame)
    size = max(10, img.height // 12)
    font = ImageFont.load_default(size=size)
    draw = ImageDraw.Draw(img)
    text = f"{seconds:.1f}s"
    box = draw.textbbox((2, 2), text, font=font)
    draw.rectangle((0, 0, box[2] + 2, box[3] + 2), fill=(0, 0, 0))
    draw.text((2, 2), text, font=font, fill=(255, 255, 255))
    return np.asarray(img)


def sample_video(path: str | Path, sampling: SamplingConfig, frames_table: pa.Table | None = None) -> SampledVideo:
    """Decode `path` with PyAV and keep the planned frames, resized to `max_pixels`."""
    import av
    from PIL import Image

    path = Path(path)
    try:
        container = av.open(str(path))
    except (FileNotFoundError, av.FFmpegError) as e:
        raise EpisodeError("video_unreadable", f"{path}: {e}") from None
    with container:
        stream = container.streams.video[0]
        total = stream.frames or sum(1 for _ in container.decode(stream))
        if not stream.frames:
            container.seek(0)
        fps = float(stream.average_rate or stream.guessed_rate or 0)
        if frames_table is not None:
            table_fps = _table_fps(frames_table, path, total)
            if fps and abs(table_fps - fps) / table_fps > FPS_TOLERANCE:
                raise EpisodeError(
                    "video_fps_mismatch", f"{path}: container says {fps} fps, frames table {table_fps:.3f}"
                )
            fps = table_fps
        if fps <= 0 or total < 1:
            raise EpisodeError("video_unreadable", f"{path}: no frame rate or no frames")
        indices, stride = plan_indices(total, fps, sampling.fps, sampling.max_frames)
        wanted = set(indices)
        size = target_size(stream.width, stream.height, sampling.max_pixels)
        kept = []
        for i, frame in enumerate(container.decode(stream)):
            if i in wanted:
                img = frame.to_image()
                if img.size != size:
                    img = img.resize(size, Image.Resampling.BICUBIC)
                arr = np.asarray(img.convert("RGB"))
                kept.append(draw_timestamp(arr, i / fps) if sampling.draw_timestamp else arr)
    if len(kept) != len(indices):
        raise EpisodeError("video_unreadable", f"{path}: decoded {len(kept)} of {len(indices)} planned frames")
    return SampledVideo(
        path=str(path),
        frames=np.stack(kept),
        frames_indices=indices,
        source_fps=fps,
        total_frames=total,
        stride=stride,
        timestamp_overlay=sampling.draw_timestamp,
    )


def jpeg_frames_data_url(video: SampledVideo, quality: int = 90) -> str:
    """`data:video/jpeg;base64,<jpg1>,<jpg2>,...` (vLLM's pre-sampled frame format)."""
    from PIL import Image

    parts = []
    for frame in video.frames:
        buf = io.BytesIO()
        Image.fromarray(frame).save(buf, format="JPEG", quality=quality)
        parts.append(base64.b64encode(buf.getvalue()).decode("ascii"))
    return "data:video/jpeg;base64," + ",".join(parts)


def mp4_data_url(video: SampledVideo) -> str:
    """The sampled frames as an H.264 MP4 at the effective rate, so container time is true time."""
    import av

    from pipeline.h264 import repeatable

    rate = Fraction(video.sample_fps).limit_denominator(1000)
    buf = io.BytesIO()
    with av.open(buf, mode="w", format="mp4") as out:
        stream = out.add_stream("libx264", rate=rate)
        stream.width, stream.height = video.frames.shape[2], video.frames.shape[1]
        stream.pix_fmt = "yuv420p"
        repeatable(stream, crf=20, preset="veryfast")  # the same video, the same request bytes
        for frame in video.frames:
            out.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
        out.mux(stream.encode())
    return "data:video/mp4;base64," + base64.b64encode(buf.getvalue()).decode("ascii")
