"""Motion primitives of the scripted expert and the controller that turns them into actions.

A primitive is one short motion with a gripper command: `Move` (proportional reach of a
grip-site waypoint, saturated, holding a top-down orientation at a given yaw) or `Grip`
(hold still while the gripper closes or opens for a number of steps). `emit` writes the
actions of a primitive for up to `n` steps, predicting the end effector's motion inside
the chunk; a chunk never spans two primitives, so the planner always decides the next
primitive from live state.

Controller facts (LIBERO OSC_POSE, measured): action[:3] = 1 asks for 5 cm per step, and
the arm follows about a quarter of that each step at steady speed (~1.2 cm/step).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

POS_SCALE = 0.05  # metres per unit action
ROT_SCALE = 0.5  # radians per unit action
FOLLOW = 0.24  # fraction of the commanded delta the arm moves per step
# grip-site rotation when pointing straight down with the fingers closing along world y
TOP_DOWN = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def hand_orientation(yaw: float, approach: np.ndarray | None = None) -> np.ndarray:
    """Top-down hand at `yaw`; or, given a horizontal `approach`, that hand tilted by 90
    degrees so it points along `approach` (fingers then close vertically when the yaw's
    closing axis is parallel to `approach`). An `approach` pointing partly down tilts the
    hand by its angle from straight down (a fist pitched into a low drawer's face)."""
    base = yaw_matrix(yaw) @ TOP_DOWN
    if approach is None:
        return base
    a = np.asarray(approach, dtype=float)
    angle = np.arccos(np.clip(-a[2] / np.linalg.norm(a), -1.0, 1.0))  # pi/2 when horizontal
    if angle < 1e-9:  # straight down: no tilt (and no axis to tilt about)
        return base
    return axis_angle_matrix(np.cross([0.0, 0.0, -1.0], a), angle) @ base


def rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Axis-angle (world frame) that rotates `current` onto `target`."""
    r = target @ current.T
    angle = np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))
    if angle < 1e-6:
        return np.zeros(3)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    n = np.linalg.norm(axis)
    if n < 1e-9:  # 180 degrees: any perpendicular axis will do
        return np.array([0.0, 0.0, angle])
    return axis / n * angle


@dataclass
class Move:
    target: np.ndarray
    gripper: float = -1.0
    speed: float = 1.0  # max |action| per position axis
    tol: float = 0.01  # metres
    yaw: float = 0.0
    max_steps: int = 80
    # switch to this gripper command once the predicted distance drops below `switch_dist`
    switch_gripper: float | None = None
    switch_dist: float = 0.0
    gain: float = 1.5
    rot_tol: float | None = None  # also wait for the orientation to be reached (radians)
    approach: np.ndarray | None = None  # horizontal pointing direction for a tilted hand
    orient: np.ndarray | None = None  # a grip-site rotation (3, 3) instead of yaw / approach
    label: str = "move"
    steps: int = field(default=0, init=False)

    def done(self, eef: np.ndarray, rot: np.ndarray) -> bool:
        if self.steps >= self.max_steps:
            return True
        if np.linalg.norm(self.target - eef) >= self.tol:
            return False
        if self.rot_tol is None:
            return True
        err = rotation_error(self.orientation(), rot)
        return float(np.linalg.norm(err)) < self.rot_tol

    def orientation(self) -> np.ndarray:
        return hand_orientation(self.yaw, self.approach) if self.orient is None else self.orient


@dataclass
class Grip:
    gripper: float
    n: int = 12
    label: str = "grip"
    steps: int = field(default=0, init=False)

    def done(self, eef: np.ndarray, rot: np.ndarray) -> bool:
        return self.steps >= self.n


Primitive = Move | Grip


def emit(
    prim: Primitive, eef: np.ndarray, rot: np.ndarray, n: int, yaw_hold: float, approach_hold: np.ndarray | None = None
) -> np.ndarray:
    """Up to `n` actions (k, 7) for `prim` from the measured pose, predicting motion."""
    out = []
    p = eef.copy()
    if isinstance(prim, Move):
        want = prim.orientation()
    else:
        want = hand_orientation(yaw_hold, approach_hold)
    rot_err = rotation_error(want, rot)
    for i in range(n):
        a = np.zeros(7)
        # orientation: hold top-down at the wanted yaw, predicting the correction made
        a[3:6] = np.clip(rot_err / ROT_SCALE * 1.5, -0.6, 0.6)
        rot_err = rot_err - a[3:6] * ROT_SCALE * FOLLOW
        if isinstance(prim, Grip):
            a[6] = prim.gripper
            if i >= prim.n - prim.steps:
                break
        else:
            err = prim.target - p
            dist = float(np.linalg.norm(err))
            if i > 0 and dist < prim.tol * 0.5:
                break  # predicted arrival: re-measure before deciding more
            a[:3] = np.clip(err / POS_SCALE * prim.gain, -prim.speed, prim.speed)
            a[6] = prim.gripper
            if prim.switch_gripper is not None and dist < prim.switch_dist:
                a[6] = prim.switch_gripper
            p = p + a[:3] * POS_SCALE * FOLLOW
        out.append(a)
    return np.array(out) if out else np.zeros((1, 7))
