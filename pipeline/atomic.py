"""Atomic writes and completion markers, shared by every stage.

A file is written to a temporary name in the same folder and renamed into place, so a
reader never sees half a file. A unit of work is done only when its marker exists, and the
marker is written last (after all of the unit's outputs), so a rerun skips exactly the
units that finished.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


@contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside `path`; rename it onto `path` if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # keep the real suffix so libraries that sniff it (np.save, pyarrow, av) behave
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix or "".join(path.suffixes))
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_bytes(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())


def write_text(path: str | Path, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=2, ensure_ascii=False, sort_keys=False) + "\n")


def write_with(path: str | Path, writer: Callable[[Path], None]) -> None:
    """Atomic write through a library call that takes a path, e.g. `lambda p: np.save(p, a)`."""
    with atomic_path(path) as tmp:
        writer(tmp)


@contextmanager
def atomic_open(path: str | Path, mode: str = "w") -> Iterator[IO]:
    with atomic_path(path) as tmp:
        with open(tmp, mode) as f:
            yield f


def file_stamp(path: Path) -> str:
    """`size:mtime_ns` of an input file ("missing" when it cannot be stat'ed): what a done
    marker records of it, so that a changed file makes its unit run again."""
    try:
        st = Path(path).stat()
    except OSError:
        return "missing"
    return f"{st.st_size}:{st.st_mtime_ns}"


class Completions:
    """Done-markers for units of work, one empty file each, under `<root>/_done/`."""

    def __init__(self, root: str | Path):
        self.dir = Path(root) / "_done"

    def _marker(self, unit_id: str) -> Path:
        return self.dir / f"{unit_id}.done"

    def is_done(self, unit_id: str) -> bool:
        return self._marker(unit_id).exists()

    def mark_done(self, unit_id: str, info: dict | None = None) -> None:
        write_json(self._marker(unit_id), info or {})

    def info(self, unit_id: str) -> dict | None:
        """What the marker recorded (e.g. the inputs the unit was computed from), None if absent."""
        try:
            return json.loads(self._marker(unit_id).read_text() or "{}")
        except (OSError, ValueError):
            return None

    def done_ids(self) -> set[str]:
        if not self.dir.exists():
            return set()
        # not the dot-named temporary file of a marker whose write was killed
        return {p.name[: -len(".done")] for p in self.dir.glob("*.done") if not p.name.startswith(".")}
