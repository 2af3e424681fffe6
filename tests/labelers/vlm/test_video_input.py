"""Frame sampling keeps true indices and times; encodings decode back to the same frames."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest

from pipeline.config import SamplingConfig
from pipeline.errors import EpisodeError
from pipeline.labelers.vlm.video_input import (
    jpeg_frames_data_url,
    mp4_data_url,
    plan_indices,
    sample_video,
    target_size,
)
from tests.labelers.vlm.factories import frame_value, frames_table, write_video


def test_plan_indices_samples_a_20hz_video_every_tenth_frame_at_2fps():
    indices, stride = plan_indices(520, 20.0, 2.0, 768)
    assert stride == 10 and indices[:3] == [0, 10, 20] and len(indices) == 52


def test_plan_indices_widens_the_stride_to_respect_max_frames():
    indices, stride = plan_indices(520, 20.0, 4.0, 40)
    assert len(indices) <= 40 and stride == 13
    assert set(np.diff(indices)) == {13}


def test_target_size_downscales_to_max_pixels_and_never_upscales():
    w, h = target_size(256, 256, 224 * 224)
    assert w * h <= 224 * 224 and w % 2 == 0 and h % 2 == 0
    assert target_size(64, 48, 224 * 224) == (64, 48)


def test_sample_video_keeps_the_planned_frames_with_true_fps(video_4s_20hz):
    path, table = video_4s_20hz
    sv = sample_video(path, SamplingConfig(fps=2.0), table)
    assert sv.source_fps == 20.0 and sv.total_frames == 80 and sv.duration_s == pytest.approx(4.0)
    assert sv.frames_indices == list(range(0, 80, 10))
    assert sv.timestamps_s == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5])
    means = sv.frames.reshape(len(sv.frames), -1).mean(axis=1)
    assert means == pytest.approx([frame_value(i, 80) for i in sv.frames_indices], abs=3)


def test_sample_video_rejects_a_frames_table_of_another_length(video_4s_20hz):
    path, _ = video_4s_20hz
    with pytest.raises(EpisodeError, match="frames table lists 79") as e:
        sample_video(path, SamplingConfig(), frames_table(79))
    assert e.value.reason == "video_table_mismatch"


def test_sample_video_rejects_a_table_whose_rate_disagrees_with_the_container(video_4s_20hz):
    path, _ = video_4s_20hz
    with pytest.raises(EpisodeError) as e:
        sample_video(path, SamplingConfig(), frames_table(80, video_fps=10))
    assert e.value.reason == "video_fps_mismatch"


def test_sample_video_names_an_unreadable_file(tmp_path):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video")
    with pytest.raises(EpisodeError, match="broken.mp4") as e:
        sample_video(bad, SamplingConfig())
    assert e.value.reason == "video_unreadable"


def test_timestamp_overlay_writes_into_the_top_left_corner_only(video_4s_20hz):
    path, table = video_4s_20hz
    plain = sample_video(path, SamplingConfig(fps=2.0), table)
    stamped = sample_video(path, SamplingConfig(fps=2.0, draw_timestamp=True), table)
    diff = np.abs(plain.frames.astype(int) - stamped.frames.astype(int)).sum(axis=-1)
    assert (diff[:, :12, :20] > 0).any(axis=(1, 2)).all()
    assert (diff[:, 30:, 40:] == 0).all()
    # different times give different stamps
    assert not np.array_equal(stamped.frames[1, :12, :20], stamped.frames[2, :12, :20])


def test_jpeg_frames_data_url_decodes_back_to_every_frame(video_4s_20hz):
    from PIL import Image

    path, table = video_4s_20hz
    sv = sample_video(path, SamplingConfig(fps=4.0), table)
    head, _, payload = jpeg_frames_data_url(sv).partition(",")
    assert head == "data:video/jpeg;base64"
    frames = [np.asarray(Image.open(io.BytesIO(base64.b64decode(p)))) for p in payload.split(",")]
    assert len(frames) == len(sv.frames_indices) == 16
    assert [f.mean() for f in frames] == pytest.approx([frame_value(i, 80) for i in sv.frames_indices], abs=4)


def test_mp4_data_url_carries_the_effective_rate_so_container_time_is_true(video_4s_20hz):
    import av

    path, table = video_4s_20hz
    sv = sample_video(path, SamplingConfig(fps=2.0), table)
    payload = mp4_data_url(sv).partition(",")[2]
    with av.open(io.BytesIO(base64.b64decode(payload))) as c:
        s = c.streams.video[0]
        n = sum(1 for _ in c.decode(s))
        assert float(s.average_rate) == pytest.approx(2.0)
    assert n == 8 and n / 2.0 == pytest.approx(sv.duration_s)


def test_sampling_without_a_table_uses_the_container_rate(tmp_path):
    path = write_video(tmp_path / "v10.mp4", 30, fps=10)
    sv = sample_video(path, SamplingConfig(fps=2.0))
    assert sv.source_fps == 10.0 and sv.frames_indices == [0, 5, 10, 15, 20, 25]
