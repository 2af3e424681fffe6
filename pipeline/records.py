"""Typed records at every stage boundary, and the run folder layout.

Raw data never changes; labels sit beside it, keyed by the stable episode key
`<suite>/<task_name>/<episode_id>`. Every artifact carries `schema_version`.

Run folder (`run.output_dir`):
    config.resolved.yaml                 the validated config of the last stage run
    stage1/episodes.parquet              one EpisodeRecord per finished episode (manifest)
    stage1/episodes/<suite>/<task>/<episode_id>/
        steps.parquet                    per-step log (STEP_SCHEMA)
        states.npy                       (steps+1, state_dim) float64 flattened MuJoCo states;
                                         row t = state before action t; last row = final state
        video_<camera>.mp4               rendered from states.npy
        frames.parquet                   frame index <-> simulator step (FRAME_SCHEMA)
        truth.parquet                    the scripted generator's own record of its attempts
                                         (pipeline/policies/scripted/truth.py; scripted only)
    stage1/_done/                        completion markers (written last)
    stage2/ ... stage3/ ... release/ ... eval/   (see each stage's module docstring)
    bench/localize_<localizer>/          `recover bench-localize` reports (pipeline/truth/bench.py)
"""

from __future__ import annotations

from enum import Enum

import pyarrow as pa
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline import SCHEMA_VERSION


class Level(str, Enum):
    L1 = "L1"  # action retry
    L2 = "L2"  # action adaptation
    L3 = "L3"  # object state recovery
    L4 = "L4"  # environmental recovery


class Category(str, Enum):
    grasp_failure = "grasp_failure"
    placement_failure = "placement_failure"
    object_displacement = "object_displacement"
    collision_or_interaction_failure = "collision_or_interaction_failure"
    environmental_obstruction = "environmental_obstruction"
    other = "other"


class Record(BaseModel):
    model_config = ConfigDict(extra="forbid")
    schema_version: int = SCHEMA_VERSION


def episode_id(policy: str, init_state: int, seed: int) -> str:
    """Stable id of an episode within its task."""
    return f"{policy}-i{init_state:02d}-s{seed}"


def episode_key(suite: str, task: str, ep_id: str) -> str:
    return f"{suite}/{task}/{ep_id}"


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
    policy_params: dict = Field(default_factory=dict)
    seed: int
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


# The stage 1 manifest (stage1/episodes.parquet): one row per EpisodeRecord, same column
# names; `policy_params` is stored as a JSON string and `videos` as a map camera -> file.
# Read it with `read_episodes` to get EpisodeRecords back.
EPISODE_SCHEMA = pa.schema(
    [
        pa.field("schema_version", pa.int32(), nullable=False),
        pa.field("suite", pa.string(), nullable=False),
        pa.field("task", pa.string(), nullable=False),
        pa.field("task_index", pa.int32(), nullable=False),
        pa.field("instruction", pa.string(), nullable=False),
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("init_state", pa.int32(), nullable=False),
        pa.field("policy", pa.string(), nullable=False),
        pa.field("policy_kind", pa.string(), nullable=False),
        pa.field("policy_params", pa.string(), nullable=False),  # JSON
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("chunk_size", pa.int32(), nullable=False),
        pa.field("horizon", pa.int32(), nullable=False),
        pa.field("control_hz", pa.int32(), nullable=False),
        pa.field("settle_steps", pa.int32(), nullable=False),
        pa.field("steps", pa.int32(), nullable=False),
        pa.field("success", pa.bool_(), nullable=False),
        pa.field("first_success_step", pa.int32()),
        pa.field("wall_time_s", pa.float64(), nullable=False),
        pa.field("state_dim", pa.int32(), nullable=False),
        pa.field("path", pa.string(), nullable=False),
        pa.field("videos", pa.map_(pa.string(), pa.string()), nullable=False),
        pa.field("video_fps", pa.int32()),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)


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
STEP_SCHEMA = pa.schema(
    [
        pa.field("step", pa.int32(), nullable=False),
        pa.field("action", pa.list_(pa.float32(), 7), nullable=False),
        pa.field("eef_pos", pa.list_(pa.float32(), 3), nullable=False),
        pa.field("eef_quat", pa.list_(pa.float32(), 4), nullable=False),  # w, x, y, z
        pa.field("gripper_qpos", pa.list_(pa.float32(), 2), nullable=False),
        pa.field("goal", pa.bool_(), nullable=False),  # goal holds after this step
        pa.field("query", pa.bool_(), nullable=False),  # a new chunk was requested at this step
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)

# Frame <-> step table of a rendered video: frame i shows the state *before* action `step`
# (the last frame may show the final state, step == steps). time_s = step / control_hz.
FRAME_SCHEMA = pa.schema(
    [
        pa.field("frame", pa.int32(), nullable=False),
        pa.field("step", pa.int32(), nullable=False),
        pa.field("time_s", pa.float64(), nullable=False),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)


def step_at_time(time_s: float, control_hz: int = 20) -> int:
    """The simulator step a time in seconds (from episode start) refers to."""
    return int(round(time_s * control_hz))


# ---- stage 2: localization -------------------------------------------------------------
class SimEvent(Record):
    """Something the simulator-state analysis saw happen (evidence for people and rules)."""

    step: int
    time_s: float
    kind: str  # grasp_missed | grasp_lost | object_dropped | object_toppled | unintended_displacement
    #            | robot_contact_non_target | object_collision | goal_regression | ...
    object: str | None = None
    other: str | None = None
    detail: str = ""


class Phases(Record):
    """Half-open step ranges [start, end) of the three phases of a failed episode."""

    pre: tuple[int, int]
    during: tuple[int, int]
    post: tuple[int, int]


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
    reason: str  # no_json | schema | out_of_range | truncated | backend_error | ...
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
EVIDENCE_SCHEMA = pa.schema(
    [
        pa.field("step", pa.int32(), nullable=False),
        pa.field("time_s", pa.float64(), nullable=False),
        pa.field("gripper_opening", pa.float32(), nullable=False),
        pa.field("grasped", pa.string(), nullable=False),  # object held between the fingers, or ""
        pa.field("contacts", pa.list_(pa.string()), nullable=False),  # "a|b" pairs, sorted names
        pa.field("displacement", pa.map_(pa.string(), pa.float32()), nullable=False),  # m from start
        pa.field("goal_progress", pa.float32(), nullable=False),  # share of goal conjuncts true
        # added by stage 2 (see pipeline/evidence.py): what the simstate rules also need
        pa.field("gripper_command", pa.float32(), nullable=False),  # gripper action (+1 close)
        pa.field("lift", pa.map_(pa.string(), pa.float32()), nullable=False),  # m, z - start z
        pa.field("tilt_deg", pa.map_(pa.string(), pa.float32()), nullable=False),  # up axis vs start
        pa.field("speed", pa.map_(pa.string(), pa.float32()), nullable=False),  # m/s, free joint
        pa.field("eef_distance", pa.map_(pa.string(), pa.float32()), nullable=False),  # grip site, m
        pa.field("position", pa.map_(pa.string(), pa.list_(pa.float32(), 3)), nullable=False),  # world xyz
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)


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
    decision: str  # accept | revise | flag
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
    resolution: str  # agreed | adjudicated
    quarantined: bool = False  # the model's output was quarantined; people supplied the values
    quarantine_reason: str | None = None
    model_proposal: AnnotationProposal
    reviews: list[AnnotationReview]
    adjudication: AnnotationAdjudication | None = None
    scene_bddl: str | None = None  # stage-2 snapshot at the *model's* failure step (relative to stage2/)
    scene_state: str | None = None
    finalized_at: str
