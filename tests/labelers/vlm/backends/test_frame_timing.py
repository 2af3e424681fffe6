"""Every Qwen family is told the true video time of every sent frame (issue 12).

For each family, a 4 fps and a 20 Hz source, and every supported sampling rate (1, 2, 4 fps),
the real processor's told times are compared with index / true fps. The 4 fps source has 49
frames, so sending every 2nd frame is the case where transformers derived 25 / 49 * 4 fps and
a 0.98 s Qwen2.5-VL step instead of 1.0.
"""

from __future__ import annotations

import importlib.util
import math
import re

import pytest

if not all(importlib.util.find_spec(m) for m in ("transformers", "torchvision", "torch")):
    pytest.skip("the `vlm` extra (torch, torchvision, transformers) is not installed", allow_module_level=True)

from pipeline.labelers.vlm.torch_compat import ensure_torchvision  # noqa: E402

ensure_torchvision()

import torch  # noqa: E402

from pipeline.config import SamplingConfig, TransformersBackendConfig  # noqa: E402
from pipeline.labelers.vlm.backends.transformers_backend import TransformersBackend  # noqa: E402
from pipeline.labelers.vlm.prompts import load_prompts  # noqa: E402
from tests.labelers.vlm.factories import frames_table, write_video  # noqa: E402
from tests.labelers.vlm.tiny_qwen import build_tiny_qwen  # noqa: E402

FAMILIES = ["qwen2_5_vl", "qwen3_vl", "qwen3_5"]
SOURCES = {"4fps_49_frames": (4, 49), "20hz_80_frames": (20, 80)}
SAMPLING_FPS = [1.0, 2.0, 4.0]
DEVICE = "cuda" if torch.cuda.is_available() else "cpu"


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory):
    return {f: build_tiny_qwen(tmp_path_factory.mktemp(f), f) for f in FAMILIES}


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    root = tmp_path_factory.mktemp("sources")
    return {
        name: (write_video(root / f"{name}.mp4", n, fps=fps), frames_table(n, video_fps=fps), fps)
        for name, (fps, n) in SOURCES.items()
    }


def _told_and_true(family: str, result, true_fps: float) -> list[tuple[float, float]]:
    """(time told, true time) per temporal group of 2 sent frames."""
    idx = result.video.frames_indices
    groups = [idx[i : i + 2] for i in range(0, len(idx), 2)]
    if family == "qwen2_5_vl":
        (step,) = result.extra["second_per_grid_ts"]
        # rotary time ids: group g sits at g * second_per_grid_ts, the time of its first frame
        return [(g * step, group[0] / true_fps) for g, group in enumerate(groups)]
    marks = [float(m) for m in re.findall(r"<([\d.]+) seconds>", " ".join(result.extra["prompt_time_marks"]))]
    assert len(marks) == len(groups)
    # the processor stamps a group with the mean time of its frames (the last one repeated if odd)
    return [(mark, (group[0] + group[-1]) / 2 / true_fps) for mark, group in zip(marks, groups)]


@pytest.mark.parametrize("sampling_fps", SAMPLING_FPS)
@pytest.mark.parametrize("source", list(SOURCES))
@pytest.mark.parametrize("family", FAMILIES)
def test_each_sent_frame_is_told_its_true_time(checkpoints, sources, family, source, sampling_fps):
    video, table, true_fps = sources[source]
    cfg = TransformersBackendConfig(model_path=checkpoints[family], max_new_tokens=1, device=DEVICE)
    backend = TransformersBackend(cfg, SamplingConfig(fps=sampling_fps), load_prompts("en"))
    result = backend.localize(video, "put the bowl on the plate", table)
    assert result.error is None
    stride = round(true_fps / sampling_fps)
    n = SOURCES[source][1]
    assert result.video.frames_indices == list(range(0, n, stride)) and result.video.source_fps == true_fps
    pairs = _told_and_true(family, result, true_fps)
    assert len(pairs) == math.ceil(len(result.video.frames_indices) / 2)
    # Qwen3 marks are printed to 0.1 s; Qwen2.5's step must be exact
    tolerance = 1e-6 if family == "qwen2_5_vl" else 0.05 + 1e-9
    assert all(abs(told - true) <= tolerance for told, true in pairs), pairs
    if family == "qwen2_5_vl":
        assert result.extra["second_per_grid_ts"] == [pytest.approx(2 * stride / true_fps, abs=1e-9)]


def test_every_second_frame_of_a_49_frame_4fps_video_is_a_one_second_qwen2_5_step(checkpoints, sources):
    """The case measured on the GPU machine: 0.98 instead of 1.0 on the landed backend."""
    video, table, _ = sources["4fps_49_frames"]
    cfg = TransformersBackendConfig(model_path=checkpoints["qwen2_5_vl"], max_new_tokens=1, device=DEVICE)
    result = TransformersBackend(cfg, SamplingConfig(fps=2.0), load_prompts("en")).localize(video, "x", table)
    assert len(result.video.frames_indices) == 25
    assert result.extra["second_per_grid_ts"] == [pytest.approx(1.0, abs=1e-9)]


def test_weights_are_placed_on_the_device_as_they_load(checkpoints):
    from pipeline.labelers.vlm.backends.transformers_backend import load_kwargs

    assert load_kwargs(torch.bfloat16, "cuda:0") == {"dtype": torch.bfloat16, "device_map": "cuda:0"}
    cfg = TransformersBackendConfig(model_path=checkpoints["qwen3_vl"], max_new_tokens=1, device=DEVICE)
    backend = TransformersBackend(cfg, SamplingConfig(), load_prompts("en"))
    devices = {p.device.type for p in backend.model.parameters()}
    assert devices == {torch.device(DEVICE).type}  # nothing left on "meta" or behind on the CPU
