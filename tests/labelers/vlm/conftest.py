"""Fixtures of the VLM tests: small real MP4s and a real loopback OpenAI-compatible server."""

from __future__ import annotations

import pytest

from tests.labelers.vlm.factories import frames_table, write_video
from tests.labelers.vlm.loopback_server import LoopbackServer


@pytest.fixture(scope="session")
def video_4s_20hz(tmp_path_factory):
    """A 4 s, 20 fps, 64x48 MP4 (80 frames) and its frames table."""
    path = write_video(tmp_path_factory.mktemp("video") / "video_agentview.mp4", 80, fps=20)
    return path, frames_table(80)


@pytest.fixture()
def server():
    with LoopbackServer(delay_s=0.3) as srv:
        yield srv
