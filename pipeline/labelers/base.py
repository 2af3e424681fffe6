"""What every labeler offers, whichever family (`simstate` rules or a `vlm` backend) it is.

- `Localizer`: failed episodes in (`Episode`: the stage-1 record, its agentview video, frame
  table and, for simstate, its evidence), one `Onset` per episode out, in input order.
- `Characterizer`: stage-2 `Localization`s in, one `Characterization` or stage-3
  `QuarantineEntry` per localization out, in input order.
Both are closed after use (`close()`: a model backend frees its server connection or GPU;
the rules have nothing to free). `pipeline.labelers.registry` builds them from the config's
backend name (simstate | openai | transformers).

`Provenance` is who produced a label (source, model, prompt name + hash, raw text): the same
five fields every Localization, Characterization and QuarantineEntry carries. `Onset` is a
localizer's answer; the VLM step stores it between stage 2's two halves as
`stage2/vlm/<suite>/<task>/<episode_id>.json` with exactly the fields that were set.
Invariant: one answer per input; a failure of one episode is an answer with a `reason`, never
an exception (a misconfiguration raises before any work).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from pydantic import BaseModel, ConfigDict, Field

from pipeline.records import Characterization, EpisodeRecord, Localization, QuarantineEntry, QuarantineReason, SimEvent

if TYPE_CHECKING:
    import pyarrow as pa

    from pipeline.evidence import Evidence
    from pipeline.labelers.vlm.backends.base import VLMResult

Progress = Callable[[], None]
CharacterizeOutcome = Characterization | QuarantineEntry
TRACE = ("model", "prompt_name", "prompt_hash", "raw_text")


class Provenance(BaseModel):
    """Who produced a label, as records carry it."""

    model_config = ConfigDict(extra="forbid")

    source: str  # simstate | openai | transformers | stage2 (a bad input)
    model: str | None = None
    prompt_name: str | None = None
    prompt_hash: str | None = None
    raw_text: str | None = None

    @classmethod
    def of(cls, result: VLMResult, source: str | None = None) -> Provenance:
        """A backend result's provenance (`source` defaults to the backend's name)."""
        return cls(source=source or result.backend, model=result.model, prompt_name=result.prompt_name,
                   prompt_hash=result.prompt_hash, raw_text=result.raw_text)

    def trace(self) -> dict[str, str | None]:
        """The fields beside `source` (model, prompt name + hash, raw text)."""
        return {k: getattr(self, k) for k in TRACE}

    def quarantine(self, key: str, stage: str, reason: QuarantineReason | str, detail: str, **extra) -> QuarantineEntry:
        return QuarantineEntry(key=key, stage=stage, source=self.source, reason=reason, detail=detail,
                               **self.trace(), **extra)


class Onset(Provenance):
    """A localizer's answer for one episode: when the failure began, or why there is no answer.

    VLM: `fail_time_s` (seconds from video start) or `reason` + `detail` (a parser or backend
    quarantine reason), with `latency_s`. simstate: `fail_step` and `fail_time_s`, the `events`
    the rules saw, and for no event `reason` "no_failure_found" with the idle `fallback_step`."""

    latency_s: float | None = None
    fail_time_s: float | None = None
    reason: QuarantineReason | None = None
    detail: str = ""
    fail_step: int | None = None
    events: list[SimEvent] = Field(default_factory=list)
    fallback_step: int | None = None

    @property
    def found(self) -> bool:
        return self.fail_time_s is not None

    def stored(self) -> dict:
        """The JSON the VLM step writes: only the fields that were set, in declaration order."""
        return self.model_dump(mode="json", exclude_unset=True)


@dataclass(frozen=True)
class Episode:
    """What a localizer may look at for one failed episode."""

    record: EpisodeRecord
    folder: Path  # the episode's stage-1 folder
    video: Path | None = None  # its agentview video, None when there is none
    frames: pa.Table | None = None  # stage 1's frame <-> step table (true frame times)
    evidence: Evidence | None = None  # simulator evidence (required by simstate)


@runtime_checkable
class Localizer(Protocol):
    name: str

    def localize(self, episodes: Sequence[Episode], progress: Progress | None = None) -> list[Onset]:
        """One Onset per episode, in input order; `progress()` after each answer."""
        ...

    def close(self) -> None: ...


@runtime_checkable
class Characterizer(Protocol):
    name: str

    def characterize(self, locs: Sequence[Localization], progress: Progress | None = None) -> list[CharacterizeOutcome]:
        """One Characterization or stage-3 QuarantineEntry per localization, in input order."""
        ...

    def close(self) -> None: ...
