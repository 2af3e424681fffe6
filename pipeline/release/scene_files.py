"""File-level checks of one released scene (no simulator needed).

Inputs: a scene's `.bddl` and `_sim_state.npy` paths. Outputs: lists of problem strings,
each starting with the file it is about. Invariant: a check never raises on bad input; it
reports it (so `recover verify` can list every problem of a copy, not the first one).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pipeline.sim.env import parse_bddl

# BDDL sections whose entries declare "name name ... - type"
_DECLARING = (":objects", ":fixtures")


def declaration_lines(text: str) -> dict[str, list[tuple[int, list[str], str]]]:
    """Per declaring section: (line number, names, type) of every `names - type` line."""
    out: dict[str, list[tuple[int, list[str], str]]] = {}
    section = None
    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(";", 1)[0].strip()
        head = re.match(r"\((:[\w-]+)", line)
        if head:
            section = head.group(1).lower() if head.group(1).lower() in _DECLARING else None
            line = line[head.end() :].strip()
            if section:
                out.setdefault(section, [])
        if section is None or not line:
            continue
        if line.startswith(")"):
            section = None
            continue
        m = re.fullmatch(r"([\w\s]+?)\s+-\s+(\w+)\s*\)?", line)
        if m:
            out[section].append((no, m.group(1).split(), m.group(2)))
            if line.endswith(")"):
                section = None
    return out


def check_bddl(path: Path) -> tuple[list[str], dict | None]:
    """LIBERO's parser accepts the file and each type's objects are declared on one line."""
    problems: list[str] = []
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        return [f"{path}: cannot read BDDL: {e}"], None
    try:
        parsed = parse_bddl(path)
    except ValueError as e:
        return [str(e)], None
    for section, decls in declaration_lines(text).items():
        lines_of: dict[str, list[int]] = {}
        for no, _names, typ in decls:
            lines_of.setdefault(typ, []).append(no)
        for typ, nos in sorted(lines_of.items()):
            if len(nos) > 1:
                problems.append(
                    f"{path}: {section} of type {typ!r} are declared on {len(nos)} lines "
                    f"({', '.join(map(str, nos))}); objects of one type must share one line"
                )
    return problems, parsed


def load_state(path: Path, state_dim: int | None = None) -> tuple[list[str], np.ndarray | None]:
    """The npy loads as a 1-D float64 vector (of `state_dim` numbers, when given)."""
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as e:
        return [f"{path}: cannot load state: {type(e).__name__}: {e}"], None
    if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.floating):
        return [f"{path}: state must be a 1-D float vector, got shape {arr.shape} dtype {arr.dtype}"], None
    if not np.all(np.isfinite(arr)):
        return [f"{path}: state holds non-finite numbers"], None
    if state_dim is not None and arr.shape[0] != state_dim:
        return [f"{path}: state has length {arr.shape[0]}, but the scene's model has state_dim {state_dim}"], None
    return [], arr.astype(np.float64)
