"""The one interface every VLM backend offers, and the result it returns.

A backend turns (video, instruction) into a `VLMResult`: the model's raw answer and thinking,
untouched, plus everything needed to trace and account for it (model, prompt name + hash,
latency, token usage, finish reason, which frames were sent). Use `run([...])` for
many videos (the `openai` backend keeps `max_in_flight` requests going); `localize` and
`characterize` are one-request conveniences. Parsing is NOT the backend's
job: `pipeline.labelers.vlm.parse.parse_localization(result, duration_s)` /
`parse_characterization(result)` turn a result into an answer or a `Quarantine`.

Errors: a request that still fails after the backend's retries comes back as a result with
`error` set (the runner quarantines it as `backend_error` and goes on); a misconfiguration
that would fail every request (wrong model name, unauthorized) raises `FatalError`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol, runtime_checkable

import pyarrow as pa
from pydantic import BaseModel, ConfigDict, Field


class VideoSent(BaseModel):
    """Which frames of which video the model saw, at which true times."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    path: str
    source_fps: float  # frames per second of the file (true time: frame i at i / source_fps)
    total_frames: int
    duration_s: float
    sample_fps: float  # effective sampling rate: source_fps / stride
    frames_indices: list[int]
    width: int
    height: int
    mode: str  # frames | mp4 | arrays (transformers)
    timestamp_overlay: bool = False


class VLMResult(BaseModel):
    model_config = ConfigDict(extra="forbid")

    backend: str  # openai | transformers
    model: str
    task: str  # localize | characterize
    prompt_name: str
    prompt_hash: str
    content: str | None = None  # the answer text (after the thinking)
    reasoning: str | None = None  # the thinking, when the server or decoder separated it
    finish_reason: str | None = None  # stop | length | ...
    latency_s: float = 0.0
    prompt_tokens: int | None = None
    completion_tokens: int | None = None
    attempts: int = 1
    error: str | None = None  # set when the request failed for good
    video: VideoSent | None = None
    extra: dict = Field(default_factory=dict)

    @property
    def raw_text(self) -> str:
        """Everything the model produced, thinking included, for quarantine and review."""
        parts = []
        if self.reasoning:
            parts.append(f"<think>\n{self.reasoning}\n</think>\n")
        if self.content:
            parts.append(self.content)
        return "".join(parts)


class VLMRequest(BaseModel):
    """One question about one video. `fail_time_s` is required for characterization."""

    model_config = ConfigDict(extra="forbid", frozen=True, arbitrary_types_allowed=True)

    task: str  # localize | characterize
    video: Path
    instruction: str
    fail_time_s: float | None = None
    frames_table: pa.Table | None = None  # stage 1's frame<->step table (true frame times)
    key: str | None = None  # episode key, echoed in `VLMResult.extra["key"]`


@runtime_checkable
class VLMBackend(Protocol):
    name: str

    def run(self, requests: list[VLMRequest], progress=None) -> list[VLMResult]:
        """Answer many requests (concurrently where the backend can), in input order.

        `progress`, if given, is called with each finished result (for a progress bar)."""
        ...

    def localize(self, video: str | Path, instruction: str, frames_table: pa.Table | None = None) -> VLMResult:
        """Ask when the failure in `video` began (answer `{"fail": seconds}`)."""
        ...

    def characterize(
        self, video: str | Path, instruction: str, fail_time_s: float, frames_table: pa.Table | None = None
    ) -> VLMResult:
        """Ask for recovery level, failure category and recovery action."""
        ...

    def close(self) -> None: ...


class BackendBase:
    """The one-request conveniences of `VLMBackend`, written once on top of `run`."""

    def run(self, requests: list[VLMRequest], progress=None) -> list[VLMResult]:  # pragma: no cover
        raise NotImplementedError

    def localize(self, video: str | Path, instruction: str, frames_table: pa.Table | None = None) -> VLMResult:
        return self.run([VLMRequest(task="localize", video=Path(video), instruction=instruction,
                                    frames_table=frames_table)])[0]

    def characterize(
        self, video: str | Path, instruction: str, fail_time_s: float, frames_table: pa.Table | None = None
    ) -> VLMResult:
        return self.run([VLMRequest(task="characterize", video=Path(video), instruction=instruction,
                                    fail_time_s=fail_time_s, frames_table=frames_table)])[0]
