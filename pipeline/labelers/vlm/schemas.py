"""Typed answers of the VLM prompts, and the reasons an answer is set aside.

- `LocalizationAnswer`: `{"fail": <seconds from video start>}`, one decimal.
- `CharacterizationAnswer`: `{"recovery_level": "L1".."L4", "failure_category": <Category>,
  "recovery_action": <short imperative>}` with `pipeline.records.Level` / `Category`.
- `Quarantine`: what the parser returns instead of an answer: a `QuarantineReason`, a
  human-readable detail and the raw text, so nothing is ever silently dropped.

Values are checked by `pipeline.labelers.vlm.parse`, which normalizes lenient-but-unambiguous forms
("l2", "Grasp Failure", "2.0") before these models validate them.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from pipeline.records import Category, Level
from pipeline.vocab import QuarantineReason  # noqa: F401 - one vocabulary for every quarantine

ACTION_MAX_CHARS = 200  # matches pipeline.records.Characterization.recovery_action


class _Answer(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class LocalizationAnswer(_Answer):
    fail: float = Field(ge=0.0)  # seconds from the start of the video, rounded to 0.1 s


class CharacterizationAnswer(_Answer):
    recovery_level: Level
    failure_category: Category
    recovery_action: str = Field(min_length=1, max_length=ACTION_MAX_CHARS)


class Quarantine(_Answer):
    reason: QuarantineReason
    detail: str = ""
    raw_text: str | None = None
