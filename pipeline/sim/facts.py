"""Typed scene facts that `SimEnv` hands to planners: plain numbers, no simulator handles.

A planner reads these instead of dicts keyed by strings, and a test builds them by hand
(synthetic boxes, regions and joints) to check geometry without a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np


@dataclass(frozen=True)
class Box:
    """A world axis-aligned box."""

    lo: np.ndarray
    hi: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        return (self.lo + self.hi) / 2

    @property
    def size(self) -> np.ndarray:
        return self.hi - self.lo


@dataclass(frozen=True)
class Region:
    """A region site (a drawer's inside, a stove's cook zone, a basket's middle)."""

    pos: np.ndarray  # world centre (3,)
    mat: np.ndarray  # world rotation (3, 3)
    size: np.ndarray  # half size in the site's frame (3,)
    parent: str | None  # the object or fixture it belongs to
    joints: tuple[str, ...] = ()  # joints that move it (a drawer's slide)


class JointKind(StrEnum):
    SLIDE = "slide"
    HINGE = "hinge"
    OTHER = "other"


@dataclass(frozen=True)
class JointFrame:
    """A joint's world frame and position now."""

    anchor: np.ndarray  # world anchor (3,)
    axis: np.ndarray  # world axis (3,)
    qpos: float
    range: np.ndarray  # (2,) limits
    kind: JointKind
