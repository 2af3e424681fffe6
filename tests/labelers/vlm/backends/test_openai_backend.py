"""The real `openai` backend client against a real OpenAI-compatible server on loopback."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from pipeline.config import OpenAIBackendConfig, SamplingConfig
from pipeline.errors import FatalError
from pipeline.labelers.vlm.backends.base import VLMRequest
from pipeline.labelers.vlm.backends.openai_backend import OpenAIBackend
from pipeline.labelers.vlm.parse import parse_characterization, parse_localization
from pipeline.labelers.vlm.prompts import load_prompts
from pipeline.labelers.vlm.schemas import LocalizationAnswer, Quarantine, QuarantineReason
from tests.labelers.vlm.factories import frame_value

INSTRUCTION = "put the black bowl on the plate"


def _backend(server, scenario="ok", sampling=None, language="en", version="v2", **cfg) -> OpenAIBackend:
    cfg = {"base_url": server.base_url, "model": scenario, "backoff_base_s": 0.01, "backoff_max_s": 0.05, **cfg}
    return OpenAIBackend(OpenAIBackendConfig(**cfg), sampling or SamplingConfig(fps=2.0), load_prompts(language, version))


def test_frames_mode_sends_sampled_frames_with_true_fps_and_indices(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, send_media_io_kwargs=True).localize(path, INSTRUCTION, table)
    (seen,) = server.seen
    assert seen.mime == "video/jpeg" and seen.n_frames == 8
    assert seen.media_io_kwargs == {
        "num_frames": -1,
        "fps": 20.0,
        "frames_indices": list(range(0, 80, 10)),
        "total_num_frames": 80,
    }
    assert seen.frame_means == pytest.approx([frame_value(i, 80) for i in range(0, 80, 10)], abs=4)
    assert INSTRUCTION in seen.text and "4.0 seconds" in seen.text and "{{" not in seen.text
    assert result.video.frames_indices == list(range(0, 80, 10)) and result.video.source_fps == 20.0
    assert result.error is None and result.finish_reason == "stop"
    assert result.content == '{"fail": 2.0}' and "gripper closes" in result.reasoning
    assert result.prompt_tokens == 1234 and result.completion_tokens == 56 and result.latency_s > 0
    assert result.prompt_name == "localize.v2.en" and len(result.prompt_hash) == 64
    assert parse_localization(result, result.video.duration_s) == LocalizationAnswer(fail=2.0)


def test_without_media_kwargs_the_body_carries_none(server, video_4s_20hz):
    path, table = video_4s_20hz
    _backend(server).localize(path, INSTRUCTION, table)
    assert "media_io_kwargs" not in server.seen[0].body and server.seen[0].n_frames == 8


def test_mp4_mode_sends_an_mp4_at_the_sampling_rate(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, video_mode="mp4", send_media_io_kwargs=True).localize(path, INSTRUCTION, table)
    (seen,) = server.seen
    assert seen.mime == "video/mp4" and seen.n_frames == 8 and seen.mp4_fps == pytest.approx(2.0)
    assert seen.media_io_kwargs == {"num_frames": -1, "fps": pytest.approx(2.0)}
    assert result.error is None


def test_max_pixels_and_thinking_switch_reach_the_server(server, tmp_path):
    from tests.labelers.vlm.factories import write_video

    path = write_video(tmp_path / "big.mp4", 20, fps=20, size=(320, 240))
    _backend(server, sampling=SamplingConfig(fps=2.0, max_pixels=160 * 120), enable_thinking=False).localize(
        path, INSTRUCTION
    )
    (seen,) = server.seen
    assert seen.size == (160, 120)
    assert seen.body["chat_template_kwargs"] == {"enable_thinking": False}


def test_reasoning_content_of_older_servers_is_read(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, "legacy").localize(path, INSTRUCTION, table)
    assert "gripper closes" in result.reasoning and result.content == '{"fail": 2.0}'


def test_answer_cut_at_token_limit_is_quarantined_never_parsed_from_thinking(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, "length").localize(path, INSTRUCTION, table)
    assert result.finish_reason == "length" and result.content is None
    got = parse_localization(result, 4.0)
    assert isinstance(got, Quarantine) and got.reason is QuarantineReason.truncated
    assert '{"fail": 2.0}' in got.raw_text  # kept for review, but not used


def test_thinking_without_answer_content_is_quarantined_as_empty(server, video_4s_20hz):
    path, table = video_4s_20hz
    got = parse_localization(_backend(server, "nocontent").localize(path, INSTRUCTION, table), 4.0)
    assert isinstance(got, Quarantine) and got.reason is QuarantineReason.empty


def test_rate_limited_request_is_retried_until_it_succeeds(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, "flaky", max_retries=4).localize(path, INSTRUCTION, table)
    assert result.error is None and result.attempts == 3 and server.calls["flaky"] == 3


def test_server_error_gives_up_after_max_retries_as_backend_error(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, "error500", max_retries=2).localize(path, INSTRUCTION, table)
    assert result.attempts == 3 and server.calls["error500"] == 3
    assert "HTTP 500" in result.error and "gave up after 3 attempts" in result.error
    got = parse_localization(result, 4.0)
    assert isinstance(got, Quarantine) and got.reason is QuarantineReason.backend_error


def test_timeout_is_retried_then_reported(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, "slow", timeout_s=0.1, max_retries=1).localize(path, INSTRUCTION, table)
    assert result.attempts == 2 and "Timeout" in result.error


def test_bad_request_is_not_retried(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, "no-such-model", max_retries=3).localize(path, INSTRUCTION, table)
    assert result.attempts == 1 and "HTTP 400" in result.error


def test_unauthorized_stops_the_run(server, video_4s_20hz):
    path, table = video_4s_20hz
    with pytest.raises(FatalError, match="HTTP 401"):
        _backend(server, "unauthorized").localize(path, INSTRUCTION, table)


def test_many_requests_keep_max_in_flight_and_come_back_in_order(server, video_4s_20hz):
    path, table = video_4s_20hz
    reqs = [
        VLMRequest(task="localize", video=Path(path), instruction=INSTRUCTION, frames_table=table, key=f"ep{i}")
        for i in range(6)
    ]
    done = []
    t0 = time.perf_counter()
    results = _backend(server, "slow", max_in_flight=3).run(reqs, progress=done.append)
    elapsed = time.perf_counter() - t0
    assert [r.extra["key"] for r in results] == [f"ep{i}" for i in range(6)] and len(done) == 6
    assert server.peak_in_flight == 3
    assert elapsed < 6 * 0.3  # overlapped, not one after another


def test_a_rate_the_server_would_misread_is_refused_before_sending(server, video_4s_20hz):
    path, table = video_4s_20hz
    result = _backend(server, sampling=SamplingConfig(fps=3.0)).localize(path, INSTRUCTION, table)
    assert result.error.startswith("sampling_rate_mismatch") and server.calls["ok"] == 0


@pytest.mark.parametrize("version", ["v1", "v2"])
def test_characterize_sends_the_failure_time_only_in_v1_and_parses_the_answer(video_4s_20hz, version):
    from tests.labelers.vlm.loopback_server import LoopbackServer

    answer = (
        '{"recovery_level": "L3", "failure_category": "object_displacement", "recovery_action": "Stand the bowl up."}'
    )
    path, table = video_4s_20hz
    with LoopbackServer(answer=answer) as srv:
        result = _backend(srv, language="zh", version=version).characterize(path, INSTRUCTION, 2.5, table)
        assert ("2.5 秒" in srv.seen[0].text) == (version == "v1") and INSTRUCTION in srv.seen[0].text
    assert result.prompt_name == f"characterize.{version}.zh"
    parsed = parse_characterization(result)
    assert parsed.recovery_level.value == "L3" and parsed.recovery_action == "Stand the bowl up."
