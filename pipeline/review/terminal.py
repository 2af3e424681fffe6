"""Text from the database as a terminal shows it: literally.

Names, labels, rationales and model names are written by reviewers, adjudicators, model
output or config; printed into an admin's terminal they must not act: rich markup
(`[bold]`, `[link=...]`) is not interpreted and control characters (escape sequences that
clear the screen, set the title or hide an OSC 8 link; carriage returns; bidi overrides)
are shown as `\\x..` / `\\u....` escapes. Every CLI table cell goes through `cell`.
"""

from __future__ import annotations

import unicodedata

from rich.text import Text


def _visible(ch: str) -> str:
    if ch == "\n" or unicodedata.category(ch) not in ("Cc", "Cf"):
        return ch
    return f"\\x{ord(ch):02x}" if ord(ch) < 0x100 else f"\\u{ord(ch):04x}"


def safe(value) -> str:
    """`value` as a string with every control character escaped (markup is still text)."""
    return "".join(_visible(ch) for ch in ("" if value is None else str(value)))


def cell(value) -> Text:
    """`value` as a rich Text: never parsed as markup, control characters escaped."""
    return Text(safe(value))
