"""Typed records at every stage boundary.

Raw data never changes; labels sit beside it, keyed by the stable episode key
`<suite>/<task_name>/<episode_id>` (`pipeline.layout.episode_key`). Every artifact carries
`schema_version`. Closed sets of values are the string enums of `pipeline.vocab`; each Parquet
file's schema is derived from its row model by `pipeline.arrow.arrow_schema` (never written by
hand). Where each record is stored in a run folder: `pipeline.layout.RunLayout`, documented
file by file in docs/data-format.md.
"""

from __future__ import annotations

from typing import Annotated

import pyarrow as pa
from annotated_types import Len
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline import SCHEMA_VERSION
from pipeline.arrow import F32, I64, JSON_TEXT, arrow_schema
from pipeline.layout import episode_key

# the vocabularies live in pipeline.vocab; importing them from here keeps working
from pipeline.vocab import Category, Decision, EventKind, Level, QuarantineReason, Resolution  # noqa: F401


class Record(BaseModel):
    model_config = ConfigDict(extra="forbid")
    schema_version: int = SCHEMA_VERSION


def episode_id(policy: str, init_state: int, seed: int) -> str:
    """Stable id of an episode within its task."""
    return f"{policy}-i{init_state:02d}-s{seed}"


_NAME = r"^[^/]+$"  # a key part and a folder name: not empty, no slash


class EpisodeRecord(Record):
    """Stage 1 output: one rollout of a failure-generator policy."""

    suite: str = Field(pattern=_NAME)
    task: str = Field(pattern=_NAME)
    task_index: int
    instruction: str
    episode_id: str = Field(pattern=_NAME)
    init_state: int
    policy: str
    policy_kind: str
    policy_params: Annotated[dict, JSON_TEXT] = Field(default_factory=dict)
    seed: I64
    chunk_size: int
    horizon: int
    control_hz: int = Field(20, gt=0)
    settle_steps: int
    steps: int = Field(ge=0)  # control steps executed by the policy (excluding settle steps)
    success: bool
    first_success_step: int | None = None
    wall_time_s: float
    state_dim: int = Field(gt=0)
    path: str  # episode folder, relative to the run's stage1/ folder
    videos: dict[str, str] = Field(default_factory=dict)  # camera -> file name
    video_fps: int | None = None

    @property
    def key(self) -> str:
        return episode_key(self.suite, self.task, self.episode_id)

    @property
    def generator(self) -> str:
        """Which generator produced it: `<kind>:<name>@<params hash>`; the hash (of the
        policy's recorded parameters: noise levels, server and its metadata, checkpoint)
        tells apart two generators of one name, e.g. the scripted expert at two noise levels."""
        import hashlib
        import json

        params = json.dumps(self.policy_params, sort_keys=True, separators=(",", ":"), default=str)
        return f"{self.policy_kind}:{self.policy}@{hashlib.sha256(params.encode()).hexdigest()[:8]}"


# The stage 1 manifest (stage1/episodes.parquet): one row per EpisodeRecord, same column
# names; `policy_params` is stored as a JSON string and `videos` as a map camera -> file.
# Read it with `read_episodes` to get EpisodeRecords back.
EPISODE_SCHEMA = arrow_schema(EpisodeRecord)


def episodes_table(records: list[EpisodeRecord]) -> pa.Table:
    import json

    rows = []
    for r in records:
        row = r.model_dump(mode="json")
        row["policy_params"] = json.dumps(row["policy_params"], sort_keys=True)
        row["videos"] = list(row["videos"].items())
        rows.append(row)
    return pa.Table.from_pylist(rows, schema=EPISODE_SCHEMA)


def read_episodes(path) -> list[EpisodeRecord]:
    """The stage 1 manifest as EpisodeRecords; a bad row raises an InputError naming the file,
    the row and the field (`read_episode_rows` sets bad rows aside instead)."""
    import json

    import pyarrow.parquet as pq

    from pipeline.errors import invalid_file

    out = []
    for i, row in enumerate(pq.read_table(path).to_pylist()):
        try:
            out.append(_episode_from_row(row))
        except json.JSONDecodeError as e:
            raise invalid_file(path, e, where=f"row {i}.policy_params") from e
        except (ValueError, TypeError) as e:  # ValidationError is a ValueError
            raise invalid_file(path, e, where=f"row {i}.") from e
    return out


def _episode_from_row(row: dict) -> EpisodeRecord:
    import json

    row = dict(row)
    row["policy_params"] = json.loads(row["policy_params"])
    row["videos"] = dict(row["videos"] or [])
    return EpisodeRecord.model_validate(row)


class ManifestProblem(BaseModel):
    """One manifest row that does not make an EpisodeRecord: which row, its key (or a stand-in
    built from the row number when the key cells are bad too), the field and why."""

    row: int
    key: str
    field: str
    detail: str
    success: bool | None  # the row's success cell when it is a bool (a success is no failure to set aside)


def read_episode_rows(path) -> tuple[list[EpisodeRecord], list[ManifestProblem]]:
    """The stage 1 manifest, row by row: one bad cell sets that row aside instead of failing
    the whole read. A file that cannot be read at all still raises (pyarrow's error)."""
    import json

    import pyarrow.parquet as pq
    from pydantic import ValidationError

    good, bad = [], []
    for i, row in enumerate(pq.read_table(path).to_pylist()):
        try:
            good.append(_episode_from_row(row))
            continue
        except json.JSONDecodeError as e:
            field, detail = "policy_params", f"not JSON ({e.msg} at char {e.pos})"
        except ValidationError as e:
            err = e.errors()[0]
            field = ".".join(str(p) for p in err["loc"]) or "<row>"
            detail = "; ".join(f"{'.'.join(str(p) for p in x['loc'])}: {x['msg']}" for x in e.errors())
        except (TypeError, ValueError) as e:  # e.g. a null map or params cell
            field, detail = "videos" if "videos" in str(e) else "policy_params", f"{type(e).__name__}: {e}"
        parts = [row.get(k) for k in ("suite", "task", "episode_id")]
        ok = all(isinstance(p, str) and p and "/" not in p for p in parts)
        key = "/".join(parts) if ok else f"unknown_suite/unknown_task/manifest_row_{i}"
        success = row.get("success") if isinstance(row.get("success"), bool) else None
        bad.append(ManifestProblem(row=i, key=key, field=field, detail=detail[:500], success=success))
    return good, bad


# Per-step log of one episode. Row t describes the step that applied action t to state t.
class StepRow(BaseModel):
    """One row of `steps.parquet`: the step that applied action t to state t."""

    step: int
    action: Annotated[list[F32], Field(min_length=7, max_length=7)]
    eef_pos: Annotated[list[F32], Field(min_length=3, max_length=3)]
    eef_quat: Annotated[list[F32], Field(min_length=4, max_length=4)]  # w, x, y, z
    gripper_qpos: Annotated[list[F32], Field(min_length=2, max_length=2)]
    goal: bool  # goal holds after this step
    query: bool  # a new chunk was requested at this step


STEP_SCHEMA = arrow_schema(StepRow)

# Frame <-> step table of a rendered video: frame i shows the state *before* action `step`
# (the last frame may show the final state, step == steps). time_s = step / control_hz.
class FrameRow(BaseModel):
    """One row of `frames.parquet`."""

    frame: int
    step: int
    time_s: float


FRAME_SCHEMA = arrow_schema(FrameRow)


def step_at_time(time_s: float, control_hz: int = 20) -> int:
    """The simulator step a time in seconds (from episode start) refers to."""
    return int(round(time_s * control_hz))


# ---- stage 2: localization -------------------------------------------------------------
class EventFields(BaseModel):
    """The fields of a simulator event, shared by `SimEvent` and the review page's copy of
    it (`review.proposal.ContextEvent`), so the two cannot drift apart."""

    step: int
    time_s: float
    kind: EventKind
    object: str | None = None
    other: str | None = None
    detail: str = ""


class PhaseFields(BaseModel):
    """Half-open step ranges [start, end) of the three phases of a failed episode."""

    pre: tuple[int, int]
    during: tuple[int, int]
    post: tuple[int, int]


# the shared fields come after `schema_version` (Record last in the bases keeps the column order)
class SimEvent(EventFields, Record):
    """Something the simulator-state analysis saw happen (evidence for people and rules)."""


class Phases(PhaseFields, Record):
    """Half-open step ranges [start, end) of the three phases of a failed episode."""


class Localization(Record):
    """Stage 2 output for one failed episode that was localized (not quarantined)."""

    key: str
    suite: str
    task: str
    episode_id: str
    instruction: str
    source: str  # simstate | openai | transformers
    model: str | None = None
    prompt_name: str | None = None
    prompt_hash: str | None = None
    raw_text: str | None = None
    fail_time_s: float
    fail_step: int
    phases: Phases
    # the scene is the first settled state at or after the onset (== fail_step when the
    # scene is already calm there): a falling or sliding object is no restorable scene.
    # Records written before this field existed snapshot the onset itself.
    scene_step: int | None = None
    scene_bddl: str  # relative to the stage2 folder
    scene_state: str
    history: str | None = None
    events: list[SimEvent] = Field(default_factory=list)
    simstate_time_s: float | None = None  # the simstate localizer's onset, when run beside a VLM

    @model_validator(mode="after")
    def _scene_step_defaults_to_onset(self) -> Localization:
        if self.scene_step is None:
            self.scene_step = self.fail_step
        elif self.scene_step < self.fail_step:
            raise ValueError(f"scene_step {self.scene_step} is before the onset fail_step {self.fail_step}")
        return self
    evidence: str | None = None  # per-step evidence parquet, relative to the stage2 folder


class QuarantineEntry(Record):
    """An output that could not be used, kept with its raw text and the reason."""

    key: str
    stage: str  # stage2 | stage3
    source: str
    reason: QuarantineReason
    detail: str = ""
    # a bad input: the file (run-relative when it lies in the run folder) and the field at fault
    file: str | None = None
    field: str | None = None
    raw_text: str | None = None
    model: str | None = None
    prompt_name: str | None = None
    prompt_hash: str | None = None
    # stage 2: where a reviewer could start looking when no onset was found (e.g. the step
    # the robot went idle), the simulator events seen, and the evidence file (stage2-relative)
    fallback_step: int | None = None
    fallback_time_s: float | None = None
    events: list[SimEvent] = Field(default_factory=list)
    evidence: str | None = None


# Per-step simulator evidence of an episode, shown to reviewers and used by simstate rules.
class EvidenceRow(BaseModel):
    """One step of an episode's evidence file (objects by name in the maps)."""

    step: int
    time_s: float
    gripper_opening: F32
    grasped: str  # object held between the fingers, or ""
    contacts: list[str]  # "a|b" pairs, sorted names
    displacement: dict[str, F32]  # m from start
    goal_progress: F32  # share of goal conjuncts true
    # added by stage 2 (see pipeline/evidence.py): what the simstate rules also need
    gripper_command: F32  # gripper action (+1 close)
    lift: dict[str, F32]  # m, z - start z
    tilt_deg: dict[str, F32]  # up axis vs start
    speed: dict[str, F32]  # m/s, free joint
    eef_distance: dict[str, F32]  # grip site, m
    position: dict[str, Annotated[list[F32], Len(3, 3)]]  # world xyz


EVIDENCE_SCHEMA = arrow_schema(EvidenceRow)


# ---- stage 3: characterization --------------------------------------------------------
class Characterization(Record):
    key: str
    recovery_level: Level
    failure_category: Category
    recovery_action: str = Field(min_length=1, max_length=200)
    source: str  # simstate | openai | transformers
    model: str | None = None
    prompt_name: str | None = None
    prompt_hash: str | None = None
    raw_text: str | None = None


# ---- stage 3: final reviewed annotations (the export of the review queue) ---------------
class AnnotationProposal(Record):
    """What the models proposed, as shown to reviewers (values are None when quarantined)."""

    fail_time_s: float | None = None
    fail_step: int | None = None
    recovery_level: Level | None = None
    failure_category: Category | None = None
    recovery_action: str | None = None
    localizer: dict = Field(default_factory=dict)  # source, model, prompt_name, prompt_hash
    characterizer: dict = Field(default_factory=dict)


class AnnotationReview(Record):
    reviewer: str
    decision: Decision
    fail_time_s: float | None = None
    fail_step: int | None = None
    recovery_level: Level | None = None
    failure_category: Category | None = None
    recovery_action: str | None = None
    edited: list[str] = Field(default_factory=list)
    flag_reason: str | None = None
    at: str


class AnnotationAdjudication(Record):
    adjudicator: str
    rationale: str
    fields: list[str]  # the disputed fields this adjudication decided
    at: str


class Annotation(Record):
    """One final, human-reviewed failure label: `annotations/<suite>/<task>/episode_<id>.json`."""

    key: str
    suite: str
    task: str
    episode_id: str
    revision: int
    instruction: str
    fail_time_s: float
    fail_step: int
    recovery_level: Level
    failure_category: Category
    recovery_action: str = Field(min_length=1, max_length=200)
    resolution: Resolution  # agreed | adjudicated (excluded items are never exported)
    quarantined: bool = False  # the model's output was quarantined; people supplied the values
    quarantine_reason: str | None = None
    model_proposal: AnnotationProposal
    reviews: list[AnnotationReview]
    adjudication: AnnotationAdjudication | None = None
    scene_bddl: str | None = None  # stage-2 snapshot at the *model's* failure step (relative to stage2/)
    scene_state: str | None = None
    finalized_at: str
