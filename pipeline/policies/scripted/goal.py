"""The task's goal as typed conjuncts: what BDDL's (:goal (And ...)) asks, one predicate each.

A `Conjunct` is still the tuple LIBERO evaluates (`("on", obj, target)`, `("open", part)`),
so it compares and hashes equal to the plain tuple `SimEnv.goal` holds; its `Predicate` is
a `StrEnum` whose values are BDDL's words, and records write the same strings as before.
"""

from __future__ import annotations

from enum import StrEnum


class Predicate(StrEnum):
    ON = "on"
    IN = "in"
    OPEN = "open"
    CLOSE = "close"
    TURNON = "turnon"
    TURNOFF = "turnoff"

    def __repr__(self) -> str:  # a conjunct prints as the plain tuple it equals
        return str.__repr__(self)


PUT = (Predicate.ON, Predicate.IN)  # an object moved onto or into something
KNOB = (Predicate.TURNON, Predicate.TURNOFF)


class Conjunct(tuple):
    """(predicate, subject[, target]): equal to, and hashed as, the plain tuple of strings."""

    __slots__ = ()

    def __new__(cls, predicate: str, subject: str, target: str | None = None) -> Conjunct:
        if predicate not in Predicate.__members__.values():
            raise ValueError(f"goal predicate {predicate!r} is not one of {tuple(p.value for p in Predicate)}")
        p = Predicate(predicate)
        return super().__new__(cls, (p, subject) if target is None else (p, subject, target))

    @classmethod
    def of(cls, raw) -> Conjunct:
        """From LIBERO's parsed goal entry (a list or tuple of strings)."""
        return raw if isinstance(raw, Conjunct) else cls(*raw)

    @property
    def predicate(self) -> Predicate:
        return self[0]

    @property
    def subject(self) -> str:
        return self[1]

    @property
    def target(self) -> str | None:
        return self[2] if len(self) > 2 else None
