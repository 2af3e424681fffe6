"""The `transformers` backend on tiny random Qwen-VL checkpoints: real processor, real generate."""

from __future__ import annotations

import importlib.util

import pytest

if not all(importlib.util.find_spec(m) for m in ("transformers", "torchvision", "torch")):
    pytest.skip("the `vlm` extra (torch, torchvision, transformers) is not installed", allow_module_level=True)

from pipeline.labelers.vlm.torch_compat import ensure_torchvision  # noqa: E402

ensure_torchvision()  # before anything imports torchvision (CPU torch needs the op shim)

import torch  # noqa: E402

from pipeline.config import SamplingConfig, TransformersBackendConfig  # noqa: E402
from pipeline.errors import ConfigError  # noqa: E402
from pipeline.labelers.vlm.backends.transformers_backend import TransformersBackend  # noqa: E402
from pipeline.labelers.vlm.parse import parse_characterization, parse_localization  # noqa: E402
from pipeline.labelers.vlm.prompts import load_prompts  # noqa: E402
from pipeline.labelers.vlm.schemas import LocalizationAnswer, Quarantine, QuarantineReason  # noqa: E402
from tests.labelers.vlm.tiny_qwen import build_tiny_qwen  # noqa: E402

INSTRUCTION = "put the black bowl on the plate"
FAMILIES = ["qwen3_vl", "qwen3_5", "qwen2_5_vl"]


class ForceText:
    """LogitsProcessor that makes generate() emit `token_ids`, then the end token."""

    def __init__(self, token_ids: list[int], eos_id: int):
        self.target, self.eos = list(token_ids), eos_id

    def __call__(self, input_ids, scores):
        seq = input_ids[0].tolist()
        # how much of the target is already written: the longest target prefix ending the sequence
        done = max((k for k in range(1, len(self.target) + 1) if seq[-k:] == self.target[:k]), default=0)
        nxt = self.target[done] if done < len(self.target) else self.eos
        forced = torch.full_like(scores, float("-inf"))
        forced[:, nxt] = 0.0
        return forced


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """family -> checkpoint folder, each built once per module."""
    built: dict[str, object] = {}

    def get(family: str):
        if family not in built:
            built[family] = build_tiny_qwen(tmp_path_factory.mktemp(family), family)
        return built[family]

    return get


@pytest.fixture(params=FAMILIES)
def checkpoint(request, tiny):
    return request.param, tiny(request.param)


def _backend(path, text: str, max_new_tokens: int = 64, sampling=None, language="en") -> TransformersBackend:
    from transformers import AutoTokenizer

    tok = AutoTokenizer.from_pretrained(path)
    force = ForceText(tok.encode(text, add_special_tokens=False), tok.convert_tokens_to_ids("<|im_end|>"))
    cfg = TransformersBackendConfig(model_path=path, max_new_tokens=max_new_tokens)
    return TransformersBackend(
        cfg, sampling or SamplingConfig(fps=2.0), load_prompts(language), logits_processors=[force]
    )


def test_forced_answer_travels_through_real_generate_and_parses(checkpoint, video_4s_20hz):
    family, path = checkpoint
    video, table = video_4s_20hz
    result = _backend(path, '<think>the gripper misses</think>{"fail": 1.5}').localize(video, INSTRUCTION, table)
    assert result.error is None and result.finish_reason == "stop" and result.backend == "transformers"
    assert result.content == '{"fail": 1.5}' and result.reasoning == "the gripper misses"
    assert result.video.frames_indices == list(range(0, 80, 10)) and result.video.source_fps == 20.0
    assert result.prompt_tokens > 8 and result.completion_tokens >= 10
    assert parse_localization(result, result.video.duration_s) == LocalizationAnswer(fail=1.5)


def test_qwen3_prompt_time_marks_follow_the_true_fps(tiny, video_4s_20hz):
    path = tiny("qwen3_vl")
    video, table = video_4s_20hz
    result = _backend(path, '{"fail": 1.0}').localize(video, INSTRUCTION, table)
    # frames 0,10,..,70 of a 20 Hz video, merged in pairs: the mark is the pair's mean time
    true = [f"<{(a + a + 10) / 2 / 20:.1f} seconds>" for a in range(0, 80, 20)]
    shrunk = [f"<{(a + a + 10) / 2 / 24:.1f} seconds>" for a in range(0, 80, 20)]
    assert (
        result.extra["prompt_time_marks"]
        == true
        == ["<0.2 seconds>", "<1.2 seconds>", "<2.2 seconds>", "<3.2 seconds>"]
    )
    assert true != shrunk


def test_qwen3_processor_without_metadata_would_shrink_time(tiny, video_4s_20hz):
    """The trap the backend avoids: bare frames are stamped at 24 fps."""
    import re

    from transformers import AutoProcessor

    from pipeline.labelers.vlm.video_input import sample_video

    path = tiny("qwen3_vl")
    proc = AutoProcessor.from_pretrained(path)
    frames = sample_video(video_4s_20hz[0], SamplingConfig(fps=2.0), video_4s_20hz[1]).frames
    text = "<|vision_start|><|video_pad|><|vision_end|>"
    ids = proc(text=[text], videos=[frames], do_sample_frames=False, return_tensors="pt")["input_ids"][0]
    marks = re.findall(r"<[\d.]+ seconds>", proc.tokenizer.decode(ids))
    assert marks and marks != ["<0.2 seconds>", "<1.2 seconds>", "<2.2 seconds>", "<3.2 seconds>"]


def test_qwen2_5_time_step_follows_the_sampling_rate(tiny, video_4s_20hz):
    path = tiny("qwen2_5_vl")
    video, table = video_4s_20hz
    for fps, step in [(2.0, 1.0), (4.0, 0.5)]:  # 2 frames per temporal group
        result = _backend(path, '{"fail": 1.0}', sampling=SamplingConfig(fps=fps)).localize(video, INSTRUCTION, table)
        assert result.extra["second_per_grid_ts"] == [pytest.approx(step)]


def test_forced_bad_answer_is_quarantined_with_its_raw_text(checkpoint, video_4s_20hz):
    _, path = checkpoint
    video, table = video_4s_20hz
    result = _backend(path, '{"fail": 99.0}').localize(video, INSTRUCTION, table)
    got = parse_localization(result, result.video.duration_s)
    assert isinstance(got, Quarantine) and got.reason is QuarantineReason.out_of_range
    assert got.raw_text == '{"fail": 99.0}'


def test_generation_cut_at_max_new_tokens_is_quarantined_as_truncated(tiny, video_4s_20hz):
    path = tiny("qwen3_vl")
    video, table = video_4s_20hz
    result = _backend(path, '<think>a very long thought</think>{"fail": 1.0}', max_new_tokens=6).localize(
        video, INSTRUCTION, table
    )
    assert result.finish_reason == "length" and result.completion_tokens == 6
    got = parse_localization(result, 4.0)
    assert isinstance(got, Quarantine) and got.reason is QuarantineReason.truncated


def test_characterization_runs_the_zh_prompt_and_parses(tiny, video_4s_20hz):
    path = tiny("qwen3_vl")
    video, table = video_4s_20hz
    answer = '{"recovery_level": "L1", "failure_category": "grasp_failure", "recovery_action": "Grasp the bowl again."}'
    result = _backend(path, answer, max_new_tokens=200, language="zh").characterize(video, INSTRUCTION, 1.5, table)
    assert result.prompt_name == "characterize.v2.zh"
    parsed = parse_characterization(result)
    assert parsed.failure_category.value == "grasp_failure" and parsed.recovery_action == "Grasp the bowl again."


def test_missing_model_path_is_a_config_error():
    with pytest.raises(ConfigError, match="model_path"):
        TransformersBackend(TransformersBackendConfig(), SamplingConfig(), load_prompts("en"))
