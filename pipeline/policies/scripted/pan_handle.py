"""Grasp of a flat, wide object by its long handle (a frying pan).

Input: a `Scene` and an object name. Output: a `Grasp` on the handle, or None when the
object has no such handle. A pan is too wide for the fingers and too low for a rim grasp
(its rim is a few centimetres of thin wall that the fingertips miss or knock over), but
its handle is a long, thin, level bar: the fingers close across it, near its root (less
torque on the grip while carrying) yet clear of the pan's rim.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.hand import Grasp
from pipeline.policies.scripted.scene import Scene

FLAT_M = 0.08  # only objects lower than this (a pot with a handle is grasped otherwise)
HANDLE_LEN_M = 0.08  # a handle part is at least this long ...
HANDLE_THICK_M = 0.035  # ... at most this thick across and high ...
HANDLE_OUT_M = 0.08  # ... and its middle this far from the centre of mass
ROOT_CLEAR_M = 0.045  # grasp point this far out along the handle from its root


def pan_handle_grasp(scene: Scene, obj: str) -> Grasp | None:
    box = scene.box(obj)
    if box.size[2] >= FLAT_M:
        return None
    com = scene.env.object_com(obj)
    parts = scene.env.object_boxes(obj)
    size = parts[:, 1] - parts[:, 0]
    centre = (parts[:, 0] + parts[:, 1]) / 2
    out = np.linalg.norm(centre[:, :2] - com[:2], axis=1)
    long = size[:, :2].max(axis=1) >= HANDLE_LEN_M
    thin = (size[:, :2].min(axis=1) <= HANDLE_THICK_M) & (size[:, 2] <= HANDLE_THICK_M)
    handle = long & thin & (out >= HANDLE_OUT_M)
    if not handle.any():
        return None
    k = int(np.argmax(np.where(handle, out, -1.0)))
    along = (centre[k, :2] - com[:2]) / out[k]  # from the pan towards the handle's tip
    corners = np.array([[x, y] for x in parts[k, :, 0] for y in parts[k, :, 1]])
    reach = (corners - com[:2]) @ along
    root, tip = float(reach.min()), float(reach.max())
    d = min(root + ROOT_CLEAR_M, (root + tip) / 2)
    pos = np.array([*(com[:2] + along * d), centre[k, 2]])
    # fingers close across the handle: closing axis perpendicular to `along`
    yaw = float(np.arctan2(along[1], along[0]))
    yaw = (yaw + np.pi / 2) % np.pi - np.pi / 2
    return Grasp(pos=pos, yaw=yaw, rim=False)
