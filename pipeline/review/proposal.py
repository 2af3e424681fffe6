"""The typed seam between stage 3 and the review queue: what the models propose for an
episode (`Proposal`) and what reviewers see beside it (`ReviewContext`).

`enqueue` validates both before an item is written and stores their JSON dumps in the
item's `proposal` / `context` columns, with only the keys the caller set (so the stored
text, and the proposal hash that makes enqueueing idempotent, are what they were when
these were plain dicts). A value that does not fit raises `InvalidProposal` naming the
field; stage 3 sets that episode aside instead of queueing the bad value.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from pipeline.records import EventFields, PhaseFields
from pipeline.vocab import Category, Level

# the proposal's values, as opposed to its model/prompt version
VALUE_FIELDS = ("fail_time_s", "fail_step", "recovery_level", "failure_category", "recovery_action")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ModelVersion(_Strict):
    """Which labeler proposed a value: backend, model and prompt version (None for simstate)."""

    source: str | None = None
    model: str | None = None
    prompt_name: str | None = None
    prompt_hash: str | None = None


class Proposal(_Strict):
    """The model's values (None when its output was quarantined) and who proposed them; the
    top-level version is the one shown beside the suggestion and written to the audit log.
    Fields in the order stage 3 writes them (the stored JSON keeps it)."""

    fail_time_s: float | None = Field(default=None, ge=0)
    fail_step: int | None = Field(default=None, ge=0)
    recovery_level: Level | None = None
    failure_category: Category | None = None
    recovery_action: str | None = Field(default=None, min_length=1, max_length=200)
    localizer: ModelVersion = ModelVersion()
    characterizer: ModelVersion = ModelVersion()
    source: str | None = None
    model: str | None = None
    prompt_name: str | None = None
    prompt_hash: str | None = None


class ContextEvent(EventFields, _Strict):
    """A simulator event shown on the timeline (records.SimEvent without its schema_version)."""


class ContextPhases(PhaseFields, _Strict):
    """The episode's phases on the timeline (records.Phases without its schema_version)."""


class ReviewContext(_Strict):
    """Media paths (relative to the run folder), timing, phases and events of one episode."""

    videos: dict[str, str] = Field(default_factory=dict)  # camera -> video file
    frames: str | None = None  # frame <-> step table
    evidence: str | None = None  # stage-2 evidence file
    fps: float | None = Field(default=None, gt=0)
    control_hz: int = Field(default=20, gt=0)
    duration_s: float | None = Field(default=None, ge=0)
    phases: ContextPhases | None = None
    events: list[ContextEvent] = Field(default_factory=list)
    scene_bddl: str | None = None
    scene_state: str | None = None
    simstate_time_s: float | None = None


class InvalidProposal(ValueError):
    """A proposal or context that does not fit its model: `field` names the first bad one
    (e.g. `proposal.fail_step`), `detail` lists them all."""

    def __init__(self, key: str, field: str, detail: str):
        super().__init__(f"{key}: field {field}: {detail}")
        self.key, self.field, self.detail = key, field, detail


def checked(model: type[BaseModel], value: BaseModel | dict, what: str, key: str) -> dict:
    """`value` validated as `model`, dumped with the keys that were set; InvalidProposal if not."""
    try:
        if isinstance(value, BaseModel):
            value = value.model_dump(mode="json", exclude_unset=True)
        return model.model_validate(value).model_dump(mode="json", exclude_unset=True)
    except ValidationError as e:
        errors = e.errors()
        fields = [".".join([what, *(str(p) for p in err["loc"])]) for err in errors]
        detail = "; ".join(f"{f}: {err['msg']}" for f, err in zip(fields, errors, strict=True))
        raise InvalidProposal(key, fields[0], detail) from None
