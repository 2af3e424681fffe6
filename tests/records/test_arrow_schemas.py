"""Every Parquet file is declared by a row model: `pipeline.arrow.arrow_schema` derives its
schema, the derived schema equals the hand-written one it replaced (so files keep their
bytes), and what each writer puts on disk has exactly that schema."""

from __future__ import annotations

from typing import Annotated

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from pydantic import BaseModel, Field

from pipeline.arrow import F32, I64, Arrow, arrow_schema
from pipeline.records import (EVIDENCE_SCHEMA, EPISODE_SCHEMA, FRAME_SCHEMA, STEP_SCHEMA, EpisodeRecord, Localization,
                              Phases, SimEvent)
from pipeline.vocab import Level
from tests.records import frozen_schemas as frozen


def _derived():
    from pipeline.eval.records import EVAL_SCHEMA
    from pipeline.policies.scripted.truth import TRUTH_SCHEMA
    from pipeline.release import lerobot_format
    from pipeline.release.manifest import SCENARIO_SCHEMA
    from pipeline.review.export import ANNOTATION_SCHEMA
    from pipeline.stage2.report import LOCALIZATION_SCHEMA

    return {"EPISODE_SCHEMA": EPISODE_SCHEMA, "STEP_SCHEMA": STEP_SCHEMA, "FRAME_SCHEMA": FRAME_SCHEMA,
            "EVIDENCE_SCHEMA": EVIDENCE_SCHEMA, "SCENARIO_SCHEMA": SCENARIO_SCHEMA, "EVAL_SCHEMA": EVAL_SCHEMA,
            "ANNOTATION_SCHEMA": ANNOTATION_SCHEMA, "TRUTH_SCHEMA": TRUTH_SCHEMA,
            "LOCALIZATION_SCHEMA": LOCALIZATION_SCHEMA, "LEROBOT_FRAME_SCHEMA": lerobot_format.FRAME_SCHEMA}


@pytest.mark.parametrize("name", sorted(_derived()))
def test_derived_schema_equals_the_hand_written_one_field_for_field(name):
    derived, before = _derived()[name], getattr(frozen, name)
    assert [str(f) for f in derived] == [str(f) for f in before]
    assert derived.equals(before, check_metadata=True)


def test_mapping_covers_optional_fixed_lists_maps_enums_and_structs():
    class Inner(BaseModel):
        a: int

    class Row(BaseModel):
        n: int
        big: I64
        x: float | None
        f: F32
        v: Annotated[list[F32], Field(min_length=3, max_length=3)]
        pair: tuple[float, float]
        m: dict[str, list[str]]
        level: Level | None
        inner: Inner
        as_json: Annotated[dict, Arrow(pa.string())]

    s = arrow_schema(Row, metadata=None)
    assert s == pa.schema([
        pa.field("n", pa.int32(), nullable=False), pa.field("big", pa.int64(), nullable=False),
        pa.field("x", pa.float64()), pa.field("f", pa.float32(), nullable=False),
        pa.field("v", pa.list_(pa.float32(), 3), nullable=False),
        pa.field("pair", pa.list_(pa.float64(), 2), nullable=False),
        pa.field("m", pa.map_(pa.string(), pa.list_(pa.string())), nullable=False), pa.field("level", pa.string()),
        pa.field("inner", pa.struct([pa.field("a", pa.int32())]), nullable=False),
        pa.field("as_json", pa.string(), nullable=False),
    ])
    assert arrow_schema(Row, nullable=True).field("n").nullable


def test_a_field_without_an_arrow_type_is_named():
    class Bad(BaseModel):
        either: int | str

    with pytest.raises(TypeError, match="Bad.either"):
        arrow_schema(Bad)


def _episode(**kw) -> EpisodeRecord:
    d = dict(suite="libero_spatial", task="t", task_index=0, instruction="pick", episode_id="p-i00-s1", init_state=0,
             policy="p", policy_kind="scripted", policy_params={"a": 1}, seed=2**40, chunk_size=8, horizon=100,
             settle_steps=10, steps=50, success=False, wall_time_s=1.5, state_dim=9, path="x/y/z",
             videos={"agentview": "video_agentview.mp4"}, video_fps=20)
    d.update(kw)
    return EpisodeRecord(**d)


def _localization(i: int, **kw) -> Localization:
    d = dict(key=f"s/t/e{i}", suite="s", task="t", episode_id=f"e{i}", instruction="x", source="simstate",
             fail_time_s=1.0, fail_step=20, phases=Phases(pre=(0, 20), during=(20, 30), post=(30, 40)),
             scene_bddl="a.bddl", scene_state="a.npy", events=[SimEvent(step=20, time_s=1.0, kind="grasp_lost")])
    d.update(kw)
    return Localization(**d)


def _written(tmp_path, name, write) -> pa.Schema:
    path = tmp_path / name
    write(path)
    return pq.read_schema(path)


def _same(written: pa.Schema, declared: pa.Schema) -> None:
    """Columns equal to the declared ones as Parquet stores them (a map read back is named
    after its column); the declared metadata is there (writers may add their own keys)."""
    buf = pa.BufferOutputStream()
    pq.write_table(declared.empty_table(), buf)
    on_disk = pq.read_schema(pa.BufferReader(buf.getvalue()))
    assert [str(f) for f in written] == [str(f) for f in on_disk]
    for k, v in (declared.metadata or {}).items():
        assert written.metadata[k] == v


def test_each_writer_puts_its_declared_schema_on_disk(tmp_path):
    from pipeline.eval.records import EVAL_SCHEMA, EvalEpisode, write_episodes
    from pipeline.evidence import write_evidence
    from pipeline.release import lerobot_format
    from pipeline.release.manifest import SCENARIO_SCHEMA, ScenarioRow, write_manifest
    from pipeline.stage1.summary import write_manifest as write_stage1_manifest
    from pipeline.stage1.video import frame_table
    from pipeline.stage2.report import LOCALIZATION_SCHEMA, write_reports
    from pipeline.atomic import write_json
    from tests.stage2.evidence_factory import make_evidence

    (tmp_path / "s1").mkdir()
    _same(pq.read_schema(write_stage1_manifest(tmp_path / "s1", [_episode()])), EPISODE_SCHEMA)
    _same(_written(tmp_path, "frames.parquet", lambda p: pq.write_table(frame_table([0, 1, 2]), p)), FRAME_SCHEMA)
    _same(_written(tmp_path, "ev.parquet", lambda p: write_evidence(p, make_evidence())), EVIDENCE_SCHEMA)
    row = ScenarioRow(suite="s", task="t", instruction="x", episode_id="e", init_state=0, step=20, fail_time_s=1.0,
                      fail_step=20, level=Level.L2, category="grasp_failure", recovery_action="retry", policy="p",
                      policy_kind="scripted", seed=1, state_dim=9, bddl_path="a.bddl", bddl_sha256="0" * 64,
                      state_path="a.npy", state_sha256="1" * 64)
    _same(_written(tmp_path, "scenarios.parquet", lambda p: write_manifest(p, [row])), SCENARIO_SCHEMA)
    ep = EvalEpisode(scene_id="s/t/e/step_0020", suite="s", task="t", instruction="x", episode_id="e", scene_step=20,
                     level="L1", policy="p", policy_kind="scripted", gripper="open", trial=0, seed=1, policy_seed=2,
                     chunk_size=8, horizon=100, offsets={"bowl": (0.01, 0.0)}, gripper_settle_steps=5,
                     init_eef_drift_m=0.0, init_gripper_opening=0.08, steps=2, success=True, wall_time_s=0.1,
                     actions=[[0.0] * 7] * 2, eef_pos=[[0.0] * 3] * 3)
    _same(_written(tmp_path, "trials.parquet", lambda p: write_episodes(p, [ep])), EVAL_SCHEMA)
    lr = lerobot_format.frame_table(np.zeros((3, 8)), np.zeros((3, 7)), 0, 0, 0, np.zeros((3, 7)))
    _same(_written(tmp_path, "lerobot.parquet", lambda p: pq.write_table(lr, p)), lerobot_format.FRAME_SCHEMA)
    s2 = tmp_path / "stage2"
    for i, loc in enumerate([_localization(0), _localization(1, model=None, events=[])]):
        write_json(s2 / "localizations" / "s" / "t" / f"e{i}.json", loc.model_dump(mode="json"))
    write_reports(s2)
    _same(pq.read_schema(s2 / "localizations.parquet"), LOCALIZATION_SCHEMA)


def test_localizations_keep_their_declared_types_when_a_column_is_all_null(tmp_path):
    """Inferred, a column with no value in any row was typed `null`; declared, it is a string."""
    from pipeline.stage2.report import localization_table

    table = localization_table([_localization(0), _localization(1)])  # simstate: no model, no prompt
    assert table.schema.field("model").type == pa.string()
    assert table.column("onset_kind").to_pylist() == ["grasp_lost", "grasp_lost"]
    assert localization_table([]).schema.names == table.schema.names  # an empty run has the columns too


def test_manifest_bytes_do_not_depend_on_enum_or_string_levels(tmp_path):
    from pipeline.release.manifest import ScenarioRow, read_manifest, write_manifest

    def row(level):
        return ScenarioRow.model_construct(**{**dict(
            suite="s", task="t", instruction="x", episode_id="e", init_state=0, step=20, fail_time_s=1.0,
            fail_step=20, category="grasp_failure", recovery_action="retry", policy="p", policy_kind="scripted",
            seed=1, localize_prompt_hash=None, characterize_prompt_hash=None, reviewers=0, adjudicated=False,
            state_dim=9, bddl_path="a.bddl", bddl_sha256="0" * 64, state_path="a.npy", state_sha256="1" * 64,
            history_paths=[], history_sha256=[], certified=None, certify_tries=0, certify_successes=0), "level": level})

    write_manifest(tmp_path / "a.parquet", [row(Level.L2)])
    write_manifest(tmp_path / "b.parquet", [row("L2")])
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()
    assert read_manifest(tmp_path / "a.parquet")[0].level is Level.L2
