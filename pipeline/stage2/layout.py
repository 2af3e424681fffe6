"""How stage 2 reads stage 1's episodes: `load_episode` checks every input it reads, and
`fingerprint` stats them. The paths come from pipeline/layout.py (`Stage1Layout`,
`Stage2Layout`); the folder layout is documented in docs/data-format.md."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic import file_stamp
from pipeline.errors import EpisodeError
from pipeline.layout import Stage1Layout, Stage2Layout
from pipeline.layout import unit_id as layout_unit_id
from pipeline.records import EpisodeRecord

# the old name of pipeline.layout.Stage2Layout, kept only for code written against it before
# the layout moved (nothing in pipeline/ uses it)
Stage2Paths = Stage2Layout


def unit_id(rec: EpisodeRecord) -> str:
    """Done-marker name of an episode (a file name: no slashes)."""
    return layout_unit_id(rec.key)


@dataclass
class Stage1Episode:
    record: EpisodeRecord
    folder: Path
    states: np.ndarray  # (steps + 1, state_dim)
    steps: dict[str, np.ndarray]  # STEP_SCHEMA columns as arrays
    frames: pa.Table | None

    def video(self, camera: str = "agentview") -> Path | None:
        return Stage1Layout.video_in(self.folder, self.record, camera)


def _bad(reason: str, path: Path, field: str, what: str) -> EpisodeError:
    return EpisodeError(reason, f"{path}: field {field}: {what}", file=str(path), field=field)


def _read_states(path: Path, rec: EpisodeRecord) -> np.ndarray:
    try:  # a truncated .npy raises ValueError (short data) or EOFError/OSError (short header)
        states = np.load(path, allow_pickle=False)
    except (ValueError, EOFError, OSError) as e:
        raise _bad("stage1_bad_states", path, "states", f"unreadable ({type(e).__name__}: {e})") from None
    if states.ndim != 2 or states.shape != (rec.steps + 1, rec.state_dim):
        raise _bad("stage1_bad_states", path, "states",
                   f"shape {states.shape}, manifest says ({rec.steps + 1}, {rec.state_dim})")
    if not np.issubdtype(states.dtype, np.floating) or not np.isfinite(states).all():
        raise _bad("stage1_bad_states", path, "states", f"dtype {states.dtype} or non-finite values")
    return states


_STEP_WIDTHS = {"step": None, "action": 7, "eef_pos": 3, "eef_quat": 4, "gripper_qpos": 2}


def _read_steps(path: Path, rec: EpisodeRecord) -> dict[str, np.ndarray]:
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as e:  # truncated: "Parquet magic bytes not found" etc.
        raise _bad("stage1_bad_steps", path, "<file>", f"unreadable ({type(e).__name__}: {e})") from None
    cols = {}
    for name, width in _STEP_WIDTHS.items():
        if name not in table.column_names:
            raise _bad("stage1_bad_steps", path, name, "column missing")
        values = table.column(name).to_pylist()
        try:  # a null or short cell makes a ragged / object array: refuse it here, not deep in the sim
            arr = np.asarray(values, dtype=np.float64 if width else np.int64)
        except (TypeError, ValueError) as e:
            raise _bad("stage1_bad_steps", path, name, f"bad cell ({e})") from None
        if (width and arr.shape != (len(values), width)) or not np.isfinite(arr).all():
            raise _bad("stage1_bad_steps", path, name, f"shape {arr.shape} or non-finite values")
        cols[name] = arr
    if len(cols["step"]) != rec.steps:
        raise _bad("stage1_bad_steps", path, "step", f"{len(cols['step'])} rows, manifest says {rec.steps}")
    return cols


def load_episode(stage1: Path, rec: EpisodeRecord) -> Stage1Episode:
    """Read an episode's logs; a missing, truncated or inconsistent file is an EpisodeError naming
    the file and the field."""
    files = Stage1Layout(Path(stage1)).episode(rec)
    folder, states_path, steps_path = files.dir, files.states, files.steps
    for p in (states_path, steps_path):
        if not p.exists():
            raise _bad("stage1_missing_file", p, "<file>", "no such file")
    states = _read_states(states_path, rec)
    cols = _read_steps(steps_path, rec)
    frames_path = files.frames
    try:
        frames = pq.read_table(frames_path) if frames_path.exists() else None
    except (pa.ArrowException, OSError) as e:
        raise _bad("stage1_bad_frames", frames_path, "<file>", f"unreadable ({type(e).__name__}: {e})") from None
    if frames is not None and not {"frame", "step", "time_s"} <= set(frames.column_names):
        raise _bad("stage1_bad_frames", frames_path, "<file>", f"columns {frames.column_names}")
    return Stage1Episode(record=rec, folder=folder, states=states, steps=cols, frames=frames)


def input_files(stage1: Path, rec: EpisodeRecord) -> list[Path]:
    """The stage-1 files an episode's stage-2 outcome is computed from."""
    files = Stage1Layout(Path(stage1)).episode(rec)
    return [files.states, files.steps, files.frames, *(files.dir / n for n in sorted(rec.videos.values()))]


def fingerprint(stage1: Path, rec: EpisodeRecord) -> dict[str, str]:
    """What an outcome was computed from: size + mtime of each input file and a hash of the
    manifest row. Recorded in the done marker; when it changes (a fixed file, a corrected
    row) the episode is done again. Stat, not a content hash: 6,500 episodes rerun in seconds."""
    import hashlib

    out = {"manifest_row": hashlib.sha256(rec.model_dump_json().encode()).hexdigest()[:16]}
    for p in input_files(stage1, rec):
        out[p.name] = file_stamp(p)
    return out
