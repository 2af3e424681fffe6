"""The request bodies of the review API (validated by FastAPI: a bad field is a 422 naming it).

Strict: JSON types are taken as they are, never coerced (`"fail_time_s": true` is not 1.0 s,
`"version": "1"` is not 1, `"exclude": 1` is not true); unknown fields are refused; every
number and string is bounded (ids and versions fit the database's 32-bit integers).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from pipeline.records import Category, Decision, Level

STRICT = ConfigDict(extra="forbid", strict=True)
MAX_INT = 2**31 - 1  # the database's INTEGER columns


class FieldsIn(BaseModel):
    """Edited fields; only the ones given count as edits."""

    model_config = STRICT
    fail_time_s: float | None = Field(default=None, ge=0, le=86_400, allow_inf_nan=False)
    recovery_level: Level | None = None
    failure_category: Category | None = None
    recovery_action: str | None = Field(default=None, min_length=1, max_length=200)

    def edits(self) -> dict:
        return self.model_dump(mode="json", exclude_unset=True)


class DecisionIn(BaseModel):
    model_config = STRICT
    decision: Decision
    fields: FieldsIn | None = None
    reason: str | None = Field(default=None, max_length=2000)
    version: int = Field(default=0, ge=0, le=MAX_INT)
    idempotency_key: str = Field(min_length=1, max_length=100)

    def payload(self) -> dict:
        """The body as `workflow.submit_review` takes it."""
        return {**self.model_dump(mode="json", exclude={"fields"}),
                "fields": self.fields.edits() if self.fields else {}}


class AdjudicationIn(BaseModel):
    model_config = STRICT
    fields: FieldsIn = FieldsIn()
    rationale: str = Field(default="", max_length=4000)
    exclude: bool = False
    version: int = Field(ge=0, le=MAX_INT)
    idempotency_key: str = Field(min_length=1, max_length=100)

    def payload(self) -> dict:
        return {**self.model_dump(mode="json", exclude={"fields"}), "fields": self.fields.edits()}


class LoginIn(BaseModel):
    model_config = STRICT
    token: str = Field(min_length=1, max_length=200)
