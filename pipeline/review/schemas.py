"""The request bodies of the review API (validated by FastAPI: a bad field is a 422 naming it)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from pipeline.records import Category, Decision, Level


class FieldsIn(BaseModel):
    """Edited fields; only the ones given count as edits."""

    model_config = ConfigDict(extra="forbid")
    fail_time_s: float | None = Field(default=None, ge=0)
    recovery_level: Level | None = None
    failure_category: Category | None = None
    recovery_action: str | None = Field(default=None, min_length=1, max_length=200)

    def edits(self) -> dict:
        return self.model_dump(mode="json", exclude_unset=True)


class DecisionIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    decision: Decision
    fields: FieldsIn | None = None
    reason: str | None = Field(default=None, max_length=2000)
    version: int = Field(default=0, ge=0)
    idempotency_key: str = Field(min_length=1, max_length=100)

    def payload(self) -> dict:
        """The body as `workflow.submit_review` takes it."""
        return {**self.model_dump(mode="json", exclude={"fields"}),
                "fields": self.fields.edits() if self.fields else {}}


class AdjudicationIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    fields: FieldsIn = FieldsIn()
    rationale: str = Field(default="", max_length=4000)
    exclude: bool = False
    version: int = Field(ge=0)
    idempotency_key: str = Field(min_length=1, max_length=100)

    def payload(self) -> dict:
        return {**self.model_dump(mode="json", exclude={"fields"}), "fields": self.fields.edits()}


class LoginIn(BaseModel):
    token: str = Field(min_length=1, max_length=200)
