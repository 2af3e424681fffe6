"""Where stage 2 reads stage 1's episodes and writes its own files (paths only, no IO
except `load_episode`). The folder layout is documented in pipeline/stage2/run.py."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.errors import EpisodeError
from pipeline.records import EpisodeRecord


@dataclass(frozen=True)
class Stage2Paths:
    root: Path  # <run>/stage2

    def _rel(self, kind: str, rec: EpisodeRecord, suffix: str) -> Path:
        return Path(kind) / rec.suite / rec.task / f"{rec.episode_id}{suffix}"

    def evidence(self, rec: EpisodeRecord) -> Path:
        return self._rel("evidence", rec, ".parquet")

    def localization(self, rec: EpisodeRecord) -> Path:
        return self._rel("localizations", rec, ".json")

    def quarantine(self, rec: EpisodeRecord) -> Path:
        return self._rel("quarantine", rec, ".json")

    def vlm(self, rec: EpisodeRecord) -> Path:
        return self._rel("vlm", rec, ".json")

    def abs(self, rel: Path) -> Path:
        return self.root / rel


def unit_id(rec: EpisodeRecord) -> str:
    """Done-marker name of an episode (a file name: no slashes)."""
    return f"{rec.suite}__{rec.task}__{rec.episode_id}"


@dataclass
class Stage1Episode:
    record: EpisodeRecord
    folder: Path
    states: np.ndarray  # (steps + 1, state_dim)
    steps: dict[str, np.ndarray]  # STEP_SCHEMA columns as arrays
    frames: pa.Table | None

    def video(self, camera: str = "agentview") -> Path | None:
        name = self.record.videos.get(camera)
        return self.folder / name if name else None


def load_episode(stage1: Path, rec: EpisodeRecord) -> Stage1Episode:
    """Read an episode's logs; a missing or inconsistent file is an EpisodeError naming it."""
    folder = Path(stage1) / rec.path
    states_path, steps_path = folder / "states.npy", folder / "steps.parquet"
    for p in (states_path, steps_path):
        if not p.exists():
            raise EpisodeError("stage1_missing_file", str(p))
    states = np.load(states_path)
    if states.ndim != 2 or states.shape != (rec.steps + 1, rec.state_dim):
        raise EpisodeError("stage1_bad_states",
                           f"{states_path}: shape {states.shape}, manifest says ({rec.steps + 1}, {rec.state_dim})")
    table = pq.read_table(steps_path)
    cols = {c: np.asarray(table.column(c).to_pylist()) for c in ("step", "action", "eef_pos", "eef_quat", "gripper_qpos")}
    if len(cols["step"]) != rec.steps:
        raise EpisodeError("stage1_bad_steps", f"{steps_path}: {len(cols['step'])} rows, manifest says {rec.steps}")
    frames_path = folder / "frames.parquet"
    frames = pq.read_table(frames_path) if frames_path.exists() else None
    return Stage1Episode(record=rec, folder=folder, states=states, steps=cols, frames=frames)
