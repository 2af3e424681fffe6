"""Evaluation episode records: one row per trial, with its trajectory, in Parquet.

Outputs (under `<run.output_dir>/eval/`):
    trials/<unit_id>.parquet   one row (EVAL_SCHEMA) per finished trial, written atomically
    _done/<unit_id>.done       the trial's completion marker, written after its row
    episodes.parquet           all rows gathered (the input of `metrics` and `report`)

Invariants: a row holds everything the metrics need (scene, task, suite, level, gripper
condition, mode, RD phase, policy, chunk size, success), so metrics are pure functions of
the rows. `unit_id` is a flat, file-safe name unique within a run.
"""

from __future__ import annotations

import re
from enum import StrEnum
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import ConfigDict, Field

from pipeline.arrow import F32, I64, arrow_schema
from pipeline.atomic import write_with
from pipeline.records import Record
from pipeline.vocab import Category, Level


class GripperCondition(StrEnum):
    open = "open"
    closed = "closed"


class TrialMode(StrEnum):
    scene = "scene"  # from a recovery scene: the RSR / RC population
    rd = "rd"  # from a state along the original failed rollout: the RD population
    official = "official"  # from LIBERO's official init state `trial`: standard LIBERO success


class RDPhase(StrEnum):
    pre = "pre"  # start state before the failure onset
    during = "during"  # while the failure unfolds (stage 2's during phase)
    post = "post"  # after it (or at or after the onset when the phases are unknown)


class EvalEpisode(Record):
    mode: TrialMode = TrialMode.scene
    scene_id: str  # <suite>/<task>/<episode>/step_<NNNN>
    suite: str
    task: str
    instruction: str
    episode_id: str  # the failed source episode
    scene_step: int  # failure onset step of the source episode
    level: Level | None = None  # from the release manifest; None when unlabeled
    category: Category | None = None
    policy: str
    policy_kind: str
    gripper: GripperCondition
    trial: int
    seed: I64  # the run seed; trial randomness derives from (seed, scene_id, trial)
    policy_seed: I64
    chunk_size: int
    horizon: int
    temporal_context: str = "none"
    offsets: dict[str, tuple[float, float]] = Field(default_factory=dict)  # object -> (dx, dy) m
    gripper_settle_steps: int
    init_eef_drift_m: float  # how far the arm moved while the gripper was initialized
    init_gripper_opening: float  # finger-joint distance after initialization, m
    rd_phase: RDPhase | None = None
    rd_start_step: int | None = None  # step of the source rollout the rerun started from
    steps: int
    success: bool
    first_success_step: int | None = None
    wall_time_s: float
    actions: list[list[F32]] = Field(default_factory=list)  # (steps, 7)
    eef_pos: list[list[F32]] = Field(default_factory=list)  # (steps + 1, 3), row 0 = start

    def unit_id(self) -> str:
        return unit_id(self.policy, self.chunk_size, self.mode.value, self.scene_id, self.gripper.value,
                       self.trial, self.rd_start_step)


def unit_id(policy: str, chunk: int, mode: str, scene_id: str, gripper: str, trial: int,
            rd_start_step: int | None = None) -> str:
    parts = [policy, f"c{chunk}", mode, scene_id, gripper, f"t{trial}"]
    if rd_start_step is not None:
        parts.append(f"s{rd_start_step:04d}")
    return re.sub(r"[^A-Za-z0-9._-]+", "_", "__".join(parts).replace("/", "__"))


EVAL_SCHEMA = arrow_schema(EvalEpisode)


def to_row(ep: EvalEpisode) -> dict:
    row = ep.model_dump(mode="json")
    row["offsets"] = [(k, list(v)) for k, v in row["offsets"].items()]
    return row


def episodes_table(episodes: list[EvalEpisode]) -> pa.Table:
    return pa.Table.from_pylist([to_row(e) for e in episodes], schema=EVAL_SCHEMA)


def write_episodes(path: str | Path, episodes: list[EvalEpisode]) -> None:
    table = episodes_table(episodes)
    write_with(path, lambda p: pq.write_table(table, p))


class MetricRow(Record):
    """A trial as the metrics and the report read it: the columns of an EvalEpisode they use."""

    model_config = ConfigDict(extra="ignore")  # a row read from the file has every column

    mode: TrialMode = TrialMode.scene
    scene_id: str
    suite: str
    task: str
    level: Level | None = None
    category: Category | None = None
    policy: str
    policy_kind: str | None = None  # the report marks the experts as reference rows
    chunk_size: int
    gripper: GripperCondition
    rd_phase: RDPhase | None = None
    success: bool


def read_rows(path: str | Path) -> list[MetricRow]:
    """The trials of an episodes file as MetricRows (the trajectories are not read)."""
    columns = [c for c in MetricRow.model_fields if c in EVAL_SCHEMA.names]
    return [MetricRow.model_validate(r) for r in pq.read_table(path, columns=columns).to_pylist()]


def read_episodes(path: str | Path) -> list[EvalEpisode]:
    rows = pq.read_table(path).to_pylist()
    for r in rows:
        r["offsets"] = {k: tuple(v) for k, v in (r["offsets"] or [])}
    return [EvalEpisode.model_validate(r) for r in rows]
