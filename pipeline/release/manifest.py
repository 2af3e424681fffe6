"""`scenarios.parquet`: the release manifest, one row per scene, with a declared schema.

Inputs: `ScenarioRow`s built by `pipeline.release.build`. Output: a Parquet file whose bytes
depend only on the rows (sorted by suite, task, episode, step; no timestamps, no absolute
paths: every path is relative to the release folder), so two builds of the same inputs
compare equal byte for byte. The checksums in it are what `recover verify` checks.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import BaseModel, ConfigDict, ValidationError

from pipeline.arrow import I64, SCHEMA_METADATA, arrow_schema
from pipeline.atomic import write_with
from pipeline.layout import RELEASE_MANIFEST
from pipeline.vocab import Category, Level, Split

MANIFEST_NAME = RELEASE_MANIFEST


class ScenarioRow(BaseModel):
    model_config = ConfigDict(extra="forbid")

    suite: str
    task: str
    instruction: str
    episode_id: str
    init_state: int
    step: int  # simulator step of the saved scene (`step_<NNNN>`)
    fail_time_s: float
    fail_step: int
    level: Level
    category: Category
    recovery_action: str
    policy: str  # the failure-generator policy
    policy_kind: str
    seed: I64
    localize_prompt_hash: str | None = None
    characterize_prompt_hash: str | None = None
    reviewers: int = 0
    adjudicated: bool = False
    state_dim: int
    bddl_path: str  # relative to the release folder
    bddl_sha256: str
    state_path: str
    state_sha256: str
    history_paths: list[str] = []
    history_sha256: list[str] = []
    certified: bool | None = None  # None: not attempted (certify_tries = 0)
    certify_tries: int = 0
    certify_successes: int = 0
    # why a scene is not certified: the recovery expert's give-up reason, `timeout` or
    # `goal_not_reached`; None when certified or not attempted
    certify_reason: str | None = None
    # train (recovery demonstrations) or eval (held out), `pipeline.release.split`; None in
    # a release built before the split
    split: Split | None = None
    # the failure generator of the source episode (`EpisodeRecord.generator`: kind, name and
    # a hash of its parameters); a release merged from several runs has several
    generator: str | None = None

    def files(self) -> list[tuple[str, str]]:
        """(relative path, sha256) of every released file of this scene."""
        return [(self.bddl_path, self.bddl_sha256), (self.state_path, self.state_sha256)] + list(
            zip(self.history_paths, self.history_sha256, strict=True)
        )


SCENARIO_SCHEMA = arrow_schema(ScenarioRow, metadata={**SCHEMA_METADATA, "name": "libero-recover scenarios"})

# columns a release built before them lacks; such a manifest still reads (they are None)
ADDED_LATER = {"certify_reason", "split", "generator"}


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def sort_key(row: ScenarioRow) -> tuple:
    return (row.suite, row.task, row.episode_id, row.step)


def write_manifest(path: str | Path, rows: list[ScenarioRow]) -> None:
    rows = sorted(rows, key=sort_key)
    cols = {f.name: [getattr(r, f.name) for r in rows] for f in SCENARIO_SCHEMA}
    table = pa.table(cols, schema=SCENARIO_SCHEMA)
    # fixed writer options: statistics and dictionary choices must not vary between builds
    write_with(path, lambda p: pq.write_table(table, p, compression="zstd", use_dictionary=True))


def read_manifest(path: str | Path) -> list[ScenarioRow]:
    """Rows of a manifest; ValueError naming the file and field if it is not one."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(path)
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowInvalid) as e:
        raise ValueError(f"{path}: not a readable Parquet manifest: {e}") from None
    missing = [f.name for f in SCENARIO_SCHEMA if f.name not in table.column_names and f.name not in ADDED_LATER]
    if missing:
        raise ValueError(f"{path}: manifest lacks column(s) {missing}")
    out = []
    for i, rec in enumerate(table.select([f.name for f in SCENARIO_SCHEMA if f.name in table.column_names]).to_pylist()):
        try:
            out.append(ScenarioRow.model_validate(rec))
        except ValidationError as e:
            raise ValueError(f"{path}: row {i} invalid: {e}") from None
    return out
