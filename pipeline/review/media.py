"""Files a reviewer may see: videos, the frame table and simulator evidence of one run.

Inputs: the run folder and a path relative to it (as stored in an item's context).
Outputs: a resolved path inside the run folder, or None; evidence and frame tables as
JSON-ready columns.
Invariants: `/media/` serves only the videos items show (`VideoAllowlist`), and nothing
outside the run's stage1/ and stage2/ folders is ever read, whatever the request says (`..`,
absolute paths, symlinks pointing out, NUL bytes, the exported labels under stage3/):
`safe_path` returns None and the API answers 404. Tables are cached by (path, mtime, size), so a rewritten file is reread.
"""

from __future__ import annotations

import os
import threading
import time
from functools import lru_cache
from pathlib import Path

from pipeline.layout import RunLayout

ALLOWED_SUFFIXES = {".mp4", ".webm", ".parquet", ".png", ".jpg", ".json"}
RELOAD_S = 2.0


class VideoAllowlist:
    """What `/media/` may serve: the videos the page shows, i.e. the paths in some item's
    `context.videos`, never a folder (a run's stage1/ also holds the generator's truth and
    the logged steps). `load` reads those paths from the database; it runs again when a
    path is not known yet (new items), at most every RELOAD_S seconds."""

    def __init__(self):
        self.paths: frozenset[str] = frozenset()
        self.loaded = float("-inf")
        self.lock = threading.Lock()

    def allows(self, rel: str, load) -> bool:
        if rel in self.paths:
            return True
        with self.lock:
            if time.monotonic() - self.loaded >= RELOAD_S:
                self.paths, self.loaded = frozenset(load()), time.monotonic()
        return rel in self.paths


def _allowed(root: Path) -> tuple[Path, Path]:
    """Only the raw episode data and its simulator evidence: stage 3 holds the exported labels
    (every reviewer's values), which a reviewer must never see."""
    layout = RunLayout(root)
    return layout.stage1.root, layout.stage2.root


def safe_path(run_dir: Path, rel: str) -> Path | None:
    if not rel or "\x00" in rel or rel.startswith(("/", "\\")) or "\\" in rel:
        return None
    root = run_dir.resolve()
    try:
        target = (root / rel).resolve(strict=True)
    except (OSError, RuntimeError):
        return None
    if not any(target.is_relative_to(folder) for folder in _allowed(root)):
        return None
    if not target.is_file() or target.suffix.lower() not in ALLOWED_SUFFIXES:
        return None
    return target


_EVIDENCE_COLUMNS = ("step", "time_s", "gripper_opening", "grasped", "contacts", "displacement", "goal_progress")


def stamp(path: Path) -> tuple[str, int, int]:
    st = os.stat(path)
    return str(path), st.st_mtime_ns, st.st_size


def evidence(path: Path) -> dict:
    """The EVIDENCE_SCHEMA table as columns; displacement becomes one series per object."""
    return _evidence(*stamp(path))


_ENCODED: dict[tuple, bytes] = {}  # (kind, path, mtime, size) -> the encoded table
_ENCODED_MAX = 256


def table_json(kind: str, path: Path) -> bytes:
    """The `kind` ("evidence" or "frames") table of `path`, encoded (cached by file stamp)."""
    import json

    key = (kind, *stamp(path))
    body = _ENCODED.get(key)
    if body is None:
        table = _evidence(*key[1:]) if kind == "evidence" else _frames(*key[1:])
        body = json.dumps(table, separators=(",", ":")).encode()
        if len(_ENCODED) >= _ENCODED_MAX:
            _ENCODED.clear()
        _ENCODED[key] = body
    return body


@lru_cache(maxsize=256)
def _evidence(path: str, _mtime: int, _size: int) -> dict:
    import json

    import pyarrow.parquet as pq

    table = pq.read_table(path, columns=list(_EVIDENCE_COLUMNS))
    meta = json.loads((table.schema.metadata or {}).get(b"evidence", b"{}"))
    t = table.to_pydict()
    objects = sorted({k for row in t["displacement"] for k, _ in (row or [])})
    disp = {o: [] for o in objects}
    for row in t["displacement"]:
        d = dict(row or [])
        for o in objects:
            v = d.get(o)
            disp[o].append(None if v is None else round(float(v), 4))
    return {
        "step": t["step"],
        "time_s": [round(x, 4) for x in t["time_s"]],
        "gripper_opening": [round(float(x), 4) for x in t["gripper_opening"]],
        "grasped": t["grasped"],
        "contacts": t["contacts"],
        "goal_progress": [round(float(x), 4) for x in t["goal_progress"]],
        "displacement": disp,
        "targets": meta.get("targets", []),
        "references": meta.get("references", []),
    }


def frames(path: Path) -> dict:
    """The FRAME_SCHEMA table as columns (frame i shows the state at `time_s[i]`)."""
    return _frames(*stamp(path))


@lru_cache(maxsize=256)
def _frames(path: str, _mtime: int, _size: int) -> dict:
    import pyarrow.parquet as pq

    t = pq.read_table(path, columns=["frame", "step", "time_s"]).to_pydict()
    return {"frame": t["frame"], "step": t["step"], "time_s": [round(x, 4) for x in t["time_s"]]}
