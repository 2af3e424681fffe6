"""VLM backend running a local Qwen-VL checkpoint (Qwen2.5-VL, Qwen3-VL, Qwen3.5) in-process.

Input: `TransformersBackendConfig.model_path` (a folder `from_pretrained` accepts; loaded
through `AutoProcessor` + `AutoModelForImageTextToText`), `VLMRequest`s.
Output: one `VLMResult` per request, like the `openai` backend: `content` is the decoded
text after the last `</think>`, `reasoning` the text before it; `finish_reason` is "length"
when generation used all `max_new_tokens` without emitting an end token.

Invariant: frames are decoded by PyAV (`video_input.sample_video`) and ALWAYS handed to the
processor with `VideoMetadata(total_num_frames, fps=<true fps>, frames_indices=[...])` and
`do_sample_frames=False`: without metadata the Qwen3 processors stamp `<t seconds>` at 24 fps
(every time shrinks by 20/24 on a 20 Hz render) and Qwen2.5-VL's time ids drift the same
way. `extra["prompt_time_marks"]` records the stamps the model actually saw and
`extra["second_per_grid_ts"]` Qwen2.5-VL's time step, so this stays checkable: the time the
model is told for each temporal group of 2 sent frames is their true time in the video
(Qwen3-VL / Qwen3.5: the mean of the two, as the processor stamps it; Qwen2.5-VL: the first,
at group index x second_per_grid_ts). See `frame_metadata` for the one subtlety.

Loading: the checkpoint goes straight to `device` (`device_map`): transformers 5 builds the
model on the meta device and loads each shard where it belongs, so a 52 GB checkpoint is
never materialized in CPU memory before a GPU copy.

Generation is greedy. `logits_processors` (constructor) are passed to `generate` on every
request (constrained decoding; tests use it to force known answers through the real path).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path

from pipeline.config import SamplingConfig, TransformersBackendConfig
from pipeline.errors import ConfigError, EpisodeError
from pipeline.labelers.vlm.backends.base import BackendBase, VLMRequest, VLMResult
from pipeline.labelers.vlm.prompts import Prompt, prompt_text
from pipeline.labelers.vlm.video_input import sample_video

THINK_END = "</think>"
_TIME_MARK = re.compile(r"<\d+(?:\.\d+)? seconds>")


def load_kwargs(dtype, device: str) -> dict:
    """`from_pretrained` arguments that place every weight on `device` as it is read."""
    return {"dtype": dtype, "device_map": device}


def frame_metadata(video, width: int, height: int):
    """The `VideoMetadata` under which every Qwen family tells each sent frame its true time.

    Qwen3-VL / Qwen3.5 stamp frames_indices / fps. Qwen2.5-VL instead derives its time step
    from `len(frames_indices) / total_num_frames * fps`, which is the sampling rate only when
    the frame count is a multiple of the stride: every 2nd frame of a 49-frame 4 fps video
    gives 25 / 49 * 4 = 2.04 fps, a 0.98 s step instead of 1.0 (2% drift). So
    `total_num_frames` is the span the sent frames stand for (count x stride); the true
    count and duration stay in `extra["video"]`.
    """
    from transformers.video_utils import VideoMetadata

    indices = list(video.frames_indices)
    return VideoMetadata(
        total_num_frames=len(indices) * video.stride,
        fps=video.source_fps,
        frames_indices=indices,
        duration=video.duration_s,
        width=width,
        height=height,
        video_backend="pyav",
    )


class TransformersBackend(BackendBase):
    name = "transformers"

    def __init__(
        self,
        cfg: TransformersBackendConfig,
        sampling: SamplingConfig,
        prompts: dict[str, Prompt],
        logits_processors: list | None = None,
    ):
        if cfg.model_path is None:
            raise ConfigError("vlm.transformers.model_path: required for the transformers backend")
        if not Path(cfg.model_path).is_dir():
            raise ConfigError(f"vlm.transformers.model_path: {cfg.model_path} is not a checkpoint folder")
        try:
            from pipeline.labelers.vlm.torch_compat import ensure_torchvision

            ensure_torchvision()
            import torch
            from transformers import AutoModelForImageTextToText, AutoProcessor
        except ImportError as e:
            raise ConfigError(
                f"the transformers backend needs the `vlm` extra (pip install -e '.[vlm]'): {e}"
            ) from None
        self.cfg, self.sampling, self.prompts = cfg, sampling, prompts
        self._torch = torch
        self.processor = AutoProcessor.from_pretrained(cfg.model_path)
        dtype = "auto" if cfg.dtype == "auto" else getattr(torch, cfg.dtype)
        model = AutoModelForImageTextToText.from_pretrained(cfg.model_path, **load_kwargs(dtype, cfg.device))
        self.model = model.eval()
        self.model_name = Path(cfg.model_path).name
        self.logits_processors = list(logits_processors or [])
        tok = self.processor.tokenizer
        self._stop_ids = {
            i
            for i in (
                tok.eos_token_id,
                tok.convert_tokens_to_ids("<|im_end|>"),
                tok.convert_tokens_to_ids("<|endoftext|>"),
            )
            if isinstance(i, int) and i >= 0
        }

    def _chat(self, text: str) -> str:
        messages = [{"role": "user", "content": [{"type": "video"}, {"type": "text", "text": text}]}]
        kwargs = {} if self.cfg.enable_thinking is None else {"enable_thinking": self.cfg.enable_thinking}
        return self.processor.apply_chat_template(messages, add_generation_prompt=True, tokenize=False, **kwargs)

    def _one(self, req: VLMRequest) -> VLMResult:
        from transformers import LogitsProcessorList

        prompt = self.prompts[req.task]
        base = dict(
            backend=self.name,
            model=self.model_name,
            task=req.task,
            prompt_name=prompt.name,
            prompt_hash=prompt.sha256,
            extra={"key": req.key} if req.key else {},
        )
        t0 = time.perf_counter()
        try:
            video = sample_video(req.video, self.sampling, req.frames_table)
        except EpisodeError as e:
            return VLMResult(**base, error=f"{e.reason}: {e.detail}")
        n, h, w = video.frames.shape[:3]
        metadata = frame_metadata(video, w, h)
        chat = self._chat(prompt_text(prompt, req.instruction, video.duration_s, req.fail_time_s))
        inputs = self.processor(
            text=[chat], videos=[video.frames], video_metadata=[metadata], do_sample_frames=False, return_tensors="pt"
        ).to(self.cfg.device)
        n_in = inputs["input_ids"].shape[1]
        with self._torch.inference_mode():
            out = self.model.generate(
                **inputs,
                max_new_tokens=self.cfg.max_new_tokens,
                do_sample=False,
                logits_processor=LogitsProcessorList(self.logits_processors),
            )
        new = out[0, n_in:].tolist()
        stopped = any(t in self._stop_ids for t in new)
        text = self.processor.tokenizer.decode(new, skip_special_tokens=True)
        reasoning, content = text.rsplit(THINK_END, 1) if THINK_END in text else (None, text)
        base["extra"].update(
            prompt_time_marks=_TIME_MARK.findall(self.processor.tokenizer.decode(inputs["input_ids"][0])),
            second_per_grid_ts=[float(x) for x in inputs.get("second_per_grid_ts", [])] or None,
        )
        return VLMResult(
            **base,
            content=content.strip(),
            reasoning=reasoning.replace("<think>", "", 1).strip() if reasoning is not None else None,
            finish_reason="stop" if stopped else "length",
            latency_s=time.perf_counter() - t0,
            prompt_tokens=n_in,
            completion_tokens=len(new),
            video=video.describe("arrays"),
        )

    def run(self, requests: list[VLMRequest], progress: Callable[[VLMResult], None] | None = None) -> list[VLMResult]:
        results = []
        for req in requests:  # one at a time: a local model is compute-bound
            results.append(self._one(req))
            if progress:
                progress(results[-1])
        return results

    def close(self) -> None:
        self.model = None
