"""VLM backend for any OpenAI-compatible chat server (vLLM, SGLang) serving a Qwen-VL model.

Input: `VLMRequest`s (video path, instruction, optional frames table / failure time).
Output: one `VLMResult` per request, in input order: answer from `message.content`, thinking
from `message.reasoning` (or `reasoning_content` on older servers), finish reason, token
usage, latency, attempts, and which frames were sent at which true times.

The video goes as one `video_url` part: pre-sampled JPEG frames
(`data:video/jpeg;base64,<jpg1>,<jpg2>,...`) or an MP4 re-encoded at the effective sampling
rate (so container time is true time). With `send_media_io_kwargs` the true fps, frame
indices and frame count ride along as vLLM's per-request `media_io_kwargs`; without it the
server's `--media-io-kwargs` fps must equal the sampling rate, which is checked per video.

Concurrency: up to `max_in_flight` requests (preparation in worker threads, then HTTP on one
asyncio + httpx client). 429, 408, 5xx, timeouts and connection errors are retried with
exponential backoff and jitter (honouring Retry-After); 401/403/404 raise `FatalError`
(every request would fail); other 4xx and exhausted retries come back as `error` results.
"""

from __future__ import annotations

import asyncio
import random
import time
from collections.abc import Callable
from pathlib import Path

import httpx

from pipeline.config import OpenAIBackendConfig, SamplingConfig
from pipeline.errors import EpisodeError, FatalError, RetryableError
from pipeline.labelers.vlm.backends.base import BackendBase, VLMRequest, VLMResult
from pipeline.labelers.vlm.prompts import Prompt, prompt_text
from pipeline.labelers.vlm.video_input import SampledVideo, jpeg_frames_data_url, mp4_data_url, sample_video

RETRY_STATUS = {408, 429, 500, 502, 503, 504}
FATAL_STATUS = {401, 403, 404}
RATE_TOLERANCE = 0.01


class OpenAIBackend(BackendBase):
    name = "openai"

    def __init__(self, cfg: OpenAIBackendConfig, sampling: SamplingConfig, prompts: dict[str, Prompt]):
        self.cfg, self.sampling, self.prompts = cfg, sampling, prompts
        self.model = cfg.model
        self.url = cfg.base_url.rstrip("/") + "/chat/completions"

    # ---- request preparation (CPU: decode, resize, encode) --------------------------------
    def prepare(self, req: VLMRequest) -> tuple[dict, SampledVideo]:
        """The JSON body for one request and the frames it carries."""
        video = sample_video(req.video, self.sampling, req.frames_table)
        if (
            not self.cfg.send_media_io_kwargs
            and abs(video.sample_fps - self.sampling.fps) > RATE_TOLERANCE * self.sampling.fps
        ):
            # the server will assume sampling.fps; any other spacing would shift every time
            raise EpisodeError(
                "sampling_rate_mismatch",
                f"{req.video}: effective rate {video.sample_fps:.3f} fps != sampling.fps "
                f"{self.sampling.fps} (source {video.source_fps} fps, {video.total_frames} frames); "
                "enable send_media_io_kwargs or adjust sampling",
            )
        prompt = self.prompts[req.task]
        text = prompt_text(prompt, req.instruction, video.duration_s, req.fail_time_s)
        if self.cfg.video_mode == "frames":
            url = jpeg_frames_data_url(video, self.sampling.jpeg_quality)
            media = {
                "num_frames": -1,
                "fps": video.source_fps,
                "frames_indices": video.frames_indices,
                "total_num_frames": video.total_frames,
            }
        else:
            url = mp4_data_url(video)
            media = {"num_frames": -1, "fps": video.sample_fps}
        body: dict = {
            "model": self.cfg.model,
            "messages": [
                {
                    "role": "user",
                    "content": [
                        {"type": "video_url", "video_url": {"url": url}},
                        {"type": "text", "text": text},
                    ],
                }
            ],
            "max_tokens": self.cfg.max_tokens,
            "temperature": self.cfg.temperature,
        }
        if self.cfg.send_media_io_kwargs:
            body["media_io_kwargs"] = {"video": media}
        if self.cfg.enable_thinking is not None:
            body["chat_template_kwargs"] = {"enable_thinking": self.cfg.enable_thinking}
        return body, video

    # ---- transport -------------------------------------------------------------------------
    def _backoff(self, attempt: int, retry_after: float | None) -> float:
        if retry_after is not None:
            return min(retry_after, self.cfg.backoff_max_s)
        return min(self.cfg.backoff_max_s, self.cfg.backoff_base_s * 2**attempt) * (0.5 + random.random() / 2)

    async def _post(self, client: httpx.AsyncClient, body: dict) -> tuple[dict | None, str | None, int]:
        """(response json, error, attempts); retries transient failures with backoff."""
        last = ""
        for attempt in range(self.cfg.max_retries + 1):
            try:
                r = await client.post(self.url, json=body, timeout=self.cfg.timeout_s)
                if r.status_code == 200:
                    return r.json(), None, attempt + 1
                if r.status_code in FATAL_STATUS:
                    raise FatalError(f"{self.url}: HTTP {r.status_code} for model {self.cfg.model!r}: {r.text[:300]}")
                if r.status_code not in RETRY_STATUS:
                    return None, f"HTTP {r.status_code}: {r.text[:500]}", attempt + 1
                header = r.headers.get("retry-after")
                raise RetryableError(
                    f"HTTP {r.status_code}: {r.text[:200]}",
                    retry_after=float(header) if header and header.replace(".", "", 1).isdigit() else None,
                )
            except (httpx.TimeoutException, httpx.TransportError) as e:
                err = RetryableError(f"{type(e).__name__}: {e}")
            except RetryableError as e:
                err = e
            last = str(err)
            if attempt < self.cfg.max_retries:
                await asyncio.sleep(self._backoff(attempt, err.retry_after))
        return None, f"{last} (gave up after {self.cfg.max_retries + 1} attempts)", self.cfg.max_retries + 1

    async def _one(self, client: httpx.AsyncClient, gate: asyncio.Semaphore, req: VLMRequest) -> VLMResult:
        prompt = self.prompts[req.task]
        base = dict(
            backend=self.name,
            model=self.cfg.model,
            task=req.task,
            prompt_name=prompt.name,
            prompt_hash=prompt.sha256,
            extra={"key": req.key} if req.key else {},
        )
        async with gate:
            t0 = time.perf_counter()
            try:
                body, video = await asyncio.to_thread(self.prepare, req)
            except EpisodeError as e:
                return VLMResult(**base, error=f"{e.reason}: {e.detail}")
            prepared = time.perf_counter()
            data, error, attempts = await self._post(client, body)
            latency = time.perf_counter() - prepared
        base["extra"]["prepare_s"] = round(prepared - t0, 4)
        if error:
            return VLMResult(
                **base, error=error, latency_s=latency, attempts=attempts, video=video.describe(self.cfg.video_mode)
            )
        try:
            choice = data["choices"][0]
            message = choice["message"]
        except (KeyError, IndexError, TypeError):
            return VLMResult(
                **base, error=f"malformed response: {str(data)[:300]}", latency_s=latency, attempts=attempts
            )
        usage = data.get("usage") or {}
        return VLMResult(
            **{**base, "model": data.get("model") or self.cfg.model},
            content=message.get("content"),
            reasoning=message.get("reasoning") or message.get("reasoning_content"),
            finish_reason=choice.get("finish_reason"),
            latency_s=latency,
            attempts=attempts,
            prompt_tokens=usage.get("prompt_tokens"),
            completion_tokens=usage.get("completion_tokens"),
            video=video.describe(self.cfg.video_mode),
        )

    async def arun(
        self, requests: list[VLMRequest], progress: Callable[[VLMResult], None] | None = None
    ) -> list[VLMResult]:
        gate = asyncio.Semaphore(self.cfg.max_in_flight)
        headers = {"Authorization": f"Bearer {self.cfg.api_key}"} if self.cfg.api_key else {}
        limits = httpx.Limits(max_connections=self.cfg.max_in_flight, max_keepalive_connections=self.cfg.max_in_flight)
        async with httpx.AsyncClient(headers=headers, limits=limits) as client:

            async def tracked(req: VLMRequest) -> VLMResult:
                result = await self._one(client, gate, req)
                if progress:
                    progress(result)
                return result

            return list(await asyncio.gather(*(tracked(r) for r in requests)))

    # ---- the VLMBackend protocol ----------------------------------------------------------
    def run(self, requests: list[VLMRequest], progress: Callable[[VLMResult], None] | None = None) -> list[VLMResult]:
        return asyncio.run(self.arun(requests, progress))

    def close(self) -> None:
        pass
