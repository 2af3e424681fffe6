"""Which renderer made a run's frames, and the one refusal of frames it no longer makes.

Every frame table (`frames.parquet`, schema metadata `renderer_version`) and history-frame
archive (`*_history_frames.npz`, array `renderer_version`) records `RENDERER_VERSION`
(pipeline/sim/render.py). A file without it was made by version 1, which drew robosuite's
collision geometry over LIBERO's meshes. What shows frames to people or models (the review
server, a VLM stage, an export of stage-1 frames) calls `require_current_frames` first and
refuses, naming the command that re-renders them from the logged states.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.errors import FatalError
from pipeline.sim.render import RENDERER_VERSION

KEY = "renderer_version"
UNSTAMPED = 1  # files from before the version was recorded
RERENDER = "recover stage1 --rerender --config <this run's config>"


def stamped(schema: pa.Schema) -> pa.Schema:
    """`schema` with the current renderer version in its metadata."""
    return schema.with_metadata({**(schema.metadata or {}), KEY.encode(): str(RENDERER_VERSION).encode()})


def frames_version(path: Path) -> int:
    """The renderer version of a `frames.parquet` (its footer only is read)."""
    meta = pq.read_schema(path).metadata or {}
    return int(meta.get(KEY.encode(), UNSTAMPED))


def history_version(archive) -> int:
    """The renderer version of an opened `*_history_frames.npz`."""
    return int(archive[KEY]) if KEY in archive.files else UNSTAMPED


def history_stamp() -> dict[str, np.ndarray]:
    return {KEY: np.asarray(RENDERER_VERSION, dtype=np.int32)}


def stale_frames(paths) -> dict[Path, int]:
    """The frame tables among `paths` that the current renderer did not make, with the version
    that did (missing ones are not stale: nothing was rendered there)."""
    return {p: v for p in map(Path, paths) if p.is_file() and (v := frames_version(p)) != RENDERER_VERSION}


def require_current_frames(paths, who: str, rerender: str = RERENDER) -> None:
    """Raise FatalError, before any work, when any frame table in `paths` is stale."""
    stale = stale_frames(paths)
    if stale:
        raise FatalError(
            f"{who} refuses frames of {len(stale)} episode(s) made by renderer version "
            f"{', '.join(map(str, sorted(set(stale.values()))))} (robosuite's collision geometry drawn over LIBERO's meshes; "
            f"now {RENDERER_VERSION}), e.g. {next(iter(stale))}; re-render them from the logged states with `{rerender}`"
        )


def run_frame_tables(cfg) -> list[Path]:
    """The frame table of every rendered episode of a run's stage 1 (a validated `Config`)."""
    from pipeline.layout import RunLayout
    from pipeline.records import read_episodes

    stage1 = RunLayout.of(cfg).stage1
    if not stage1.manifest.is_file():
        return []
    return [stage1.episode(r).frames for r in read_episodes(stage1.manifest) if r.videos]
