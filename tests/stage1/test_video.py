"""Frame <-> step mapping and MP4 encoding (no simulator needed)."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.records import step_at_time
from pipeline.stage1.video import frame_steps, read_video, write_videos


def test_frames_sample_every_stride_and_end_on_the_final_state():
    assert frame_steps(10, fps=10) == [0, 2, 4, 6, 8, 10]
    assert frame_steps(9, fps=10) == [0, 2, 4, 6, 8, 9]
    assert frame_steps(3, fps=20) == [0, 1, 2, 3]
    assert frame_steps(0, fps=5) == [0]


def test_frame_steps_reject_fps_that_does_not_divide_the_control_rate():
    with pytest.raises(ValueError, match="divide"):
        frame_steps(10, fps=3)


def test_videos_have_one_frame_per_frame_table_row_and_times_map_back_to_steps(tmp_path):
    steps = frame_steps(13, fps=5)  # [0, 4, 8, 12, 13]
    frames = [np.full((32, 32, 3), 40 * i, dtype=np.uint8) for i in range(len(steps))]
    videos = write_videos({"agentview": frames}, steps, tmp_path, fps=5)
    assert videos == {"agentview": "video_agentview.mp4"}
    decoded = read_video(tmp_path / "video_agentview.mp4")
    assert len(decoded) == len(steps)
    # H.264 is lossy, but flat grey levels survive closely
    assert [int(round(f.mean())) for f in decoded] == pytest.approx([40 * i for i in range(len(steps))], abs=3)
    table = pq.read_table(tmp_path / "frames.parquet").to_pylist()
    assert [r["step"] for r in table] == steps
    assert all(step_at_time(r["time_s"]) == r["step"] for r in table)
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_write_videos_refuses_a_frame_count_that_does_not_match(tmp_path):
    with pytest.raises(ValueError, match="frames for"):
        write_videos({"agentview": [np.zeros((16, 16, 3), np.uint8)]}, [0, 2], tmp_path, fps=10)
