"""Normalize a LIBERO BDDL so objects sharing a type are declared on one line.

Input: BDDL text. Output: the same text with each `(:objects ...)` and `(:fixtures ...)`
section rewritten as one `name name ... - type` line per type, types in order of first
appearance, names in order of appearance; everything else is byte-identical. Names without
a type (LIBERO files them under `object` / `fixture`) stay, untyped, on a last line.

Why: LIBERO's parser assigns `objects[type] = names` per declaration line, so a type spread
over two lines silently loses the first line's objects. Merging never changes the order in
which LIBERO creates a scene's objects when each type already sat on one line (all 130
shipped tasks), so a state saved from the original environment restores in the new one.
"""

from __future__ import annotations

import re

SECTIONS = (":objects", ":fixtures")


def _section_span(text: str, head: str) -> tuple[int, int] | None:
    """[start, end) of `(head ... )`, matching parentheses; None if absent."""
    m = re.search(r"\(\s*" + re.escape(head) + r"\b", text, flags=re.IGNORECASE)
    if not m:
        return None
    depth = 0
    for i in range(m.start(), len(text)):
        if text[i] == "(":
            depth += 1
        elif text[i] == ")":
            depth -= 1
            if depth == 0:
                return m.start(), i + 1
    raise ValueError(f"unbalanced parentheses in the {head} section")


def declarations(body: str) -> tuple[list[tuple[str, str]], list[str]]:
    """(name, type) pairs in order, and untyped trailing names, of a section's body."""
    tokens = re.sub(r";[^\n]*", " ", body).split()
    typed, pending = [], []
    i = 0
    while i < len(tokens):
        if tokens[i] == "-":
            if i + 1 >= len(tokens):
                raise ValueError("a '-' without a type at the end of a declaration")
            typed += [(n, tokens[i + 1]) for n in pending]
            pending = []
            i += 2
        else:
            pending.append(tokens[i])
            i += 1
    return typed, pending


def section_declarations(text: str, head: str) -> tuple[list[tuple[str, str]], list[str]]:
    span = _section_span(text, head)
    if span is None:
        return [], []
    inner = text[span[0] : span[1]]
    body = re.sub(r"^\(\s*" + re.escape(head), "", inner, flags=re.IGNORECASE)[:-1]
    return declarations(body)


def _render(head: str, typed: list[tuple[str, str]], untyped: list[str], indent: str) -> str:
    by_type: dict[str, list[str]] = {}
    for name, typ in typed:
        names = by_type.setdefault(typ, [])
        if name not in names:
            names.append(name)
    lines = [f"{indent}  {' '.join(names)} - {typ}" for typ, names in by_type.items()]
    if untyped:
        lines.append(f"{indent}  {' '.join(untyped)}")
    return f"({head}\n" + "\n".join(lines) + f"\n{indent})"


def normalize_bddl(text: str) -> str:
    out = text
    for head in SECTIONS:
        span = _section_span(out, head)
        if span is None:
            continue
        line_start = out.rfind("\n", 0, span[0]) + 1
        indent = re.match(r"[ \t]*", out[line_start : span[0]]).group(0)
        typed, untyped = section_declarations(out, head)
        out = out[: span[0]] + _render(head, typed, untyped, indent) + out[span[1] :]
    return out
