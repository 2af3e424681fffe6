"""The Panda hand pointing down: a grasp, and the axis its fingers close along.

Geometry only (numbers in, numbers out). The fingers open to about 8 cm and close along
R_z(yaw) * world-y; yaw and yaw + pi close along the same line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FINGER_REACH = 0.047  # open fingertip centre from the grip site


@dataclass(frozen=True)
class Grasp:
    pos: np.ndarray
    yaw: float  # 0: fingers close along world y
    rim: bool


def closing_axis(yaw: float) -> np.ndarray:
    return np.array([-np.sin(yaw), np.cos(yaw), 0.0])


def closing_yaw(direction: np.ndarray) -> float:
    """A top-down hand yaw whose `closing_axis` is the horizontal `direction` (in (-pi, pi];
    yaw + pi closes along it too)."""
    return float(np.arctan2(-direction[0], direction[1]))


def closing_yaw_near(direction: np.ndarray, near: float) -> float:
    """Of the yaws closing along `direction` (either sign, any turn by pi), the one nearest `near`."""
    base = closing_yaw(direction)
    return min((base, base - np.pi, base + np.pi), key=lambda y: abs(y - near))
