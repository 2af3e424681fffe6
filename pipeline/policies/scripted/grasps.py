"""Where to grasp an object: grip-site position and hand yaw.

Input: a `Scene` and an object name. Output: a `Grasp`. The Panda's fingers open to
about 8 cm and close along R_z(yaw) * world-y when pointing down. Objects whose width
along some closing direction fits between the fingers are grasped around their middle
(the narrowest direction, preferring little wrist turn); wider ones (bowls, plates, mugs,
pans) by their rim wall, at the side where the outer finger lands on free space. Finger
landing spots are probed with vertical rays through the live scene.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted.hand import FINGER_REACH, Grasp, closing_axis, closing_yaw
from pipeline.policies.scripted.pan_handle import pan_handle_grasp
from pipeline.policies.scripted.reach import overreach
from pipeline.policies.scripted.scene import TABLE_MARGIN, Scene

MAX_SPAN = 0.068  # widest object (along the closing axis) grasped whole
RIM_INSET = 0.012  # grasp point inside the outer rim edge
RIM_DEPTH = 0.02  # grip site below the rim top
LONG_M = 0.12  # horizontal length beyond which a whole-object grasp goes to the centre of mass
TALL_M = 0.11  # objects taller than this may be carried by a handle
HANDLE_THIN_M, HANDLE_OUT_M = 0.016, 0.055  # a handle part: thinner than this, this far out
UPRIGHT_COS = np.cos(np.radians(20))  # body axis this close to vertical: standing upright
# an object whose own up axis is this far from vertical leans on something (less: it stands;
# past LEAN_MAX it lies on its side, a pose with its own grasps)
LEAN_MIN, LEAN_MAX = np.radians(10), np.radians(75)
YAW_BAND = np.radians(20)  # a handle's yaw range reaches this far past pi/2 (see handle_grasp)
YAWS = np.linspace(-np.pi / 2, np.pi / 2, 12, endpoint=False)
# a standing book: thinner than SLAB_THIN_M, taller than SLAB_TALL_M, long. It is held near
# its top edge so the fingers stay above a compartment's walls when it goes in (slot.py)
SLAB_THIN_M, SLAB_TALL_M, SLAB_RATIO = 0.04, 0.09, 2.5
SLAB_GRIP_BELOW_TOP = 0.028


def is_upright_slab(scene: Scene, obj: str) -> bool:
    """A thin, tall, long object standing on its edge (a book)."""
    xy = scene.env.object_corners(obj)[:, :2]
    widths = [float(np.ptp(xy @ [np.cos(t), np.sin(t)])) for t in np.linspace(0, np.pi, 90, endpoint=False)]
    thin, long = min(widths), max(widths)
    return thin < SLAB_THIN_M and long > SLAB_RATIO * thin and scene.box(obj).size[2] > SLAB_TALL_M


def blocked_depth(scene: Scene, pos: np.ndarray, yaw: float, top: float, skip_tips: bool = False) -> float:
    """How far (m) anything sticks up into the hand's way when the grip site is at `pos`:
    under both fingertips (unless `skip_tips`) and under the palm's ends (about 6 cm above
    the tips)."""
    ax = closing_axis(yaw)
    side = np.array([-ax[1], ax[0], 0.0])
    tip_z = pos[2] - 0.012
    probes = [] if skip_tips else [(pos + s * ax * FINGER_REACH, tip_z) for s in (-1, 1)]
    # the hand's collision box reaches ~0.10 m along the closing axis, from ~5 cm above the site
    probes += [
        (pos + s * ax * r + t * side * 0.03, pos[2] + 0.05) for s in (-1, 1) for t in (-1, 1) for r in (0.05, 0.1)
    ]
    worst = 0.0
    for point, z in probes:
        for dx, dy in ((0, 0), (0.008, 0), (-0.008, 0), (0, 0.008), (0, -0.008)):
            # start well above everything: a ray starting inside a geom would not see it
            hit = scene.env.ray_down(point[:2] + [dx, dy], max(top, z) + 0.4, z)
            if hit is not None:
                worst = max(worst, hit - z)
    return worst


def object_frame_boxes(scene: Scene, obj: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The object's collision boxes (k, 2, 3) in its own body frame, the body position, its
    rotation (columns: body axes in world) and the centre of mass in the body frame. World
    boxes of a turned object are wider than its parts: a thin part is thin only here."""
    env = scene.env
    pos, rot = env.object_frame(obj)
    local = (env.object_corners(obj).reshape(-1, 8, 3) - pos) @ rot
    return np.stack([local.min(axis=1), local.max(axis=1)], axis=1), pos, rot, (env.object_com(obj) - pos) @ rot


def handle_grasp(scene: Scene, obj: str) -> Grasp | None:
    """A tall object with a thin handle sticking out of its body (a moka pot): grasp the
    handle across its thin side, at mid-height. Its top edge (what a rim grasp finds) slips.
    Found in the object's own frame, so a pot turned by any yaw is still seen to have one
    (in world boxes a turned handle is not thin); only while it stands upright."""
    boxes, body, rot, com = object_frame_boxes(scene, obj)
    if rot[2, 2] < UPRIGHT_COS or float(boxes[:, 1, 2].max() - boxes[:, 0, 2].min()) < TALL_M:
        return None
    size = boxes[:, 1] - boxes[:, 0]
    centre = (boxes[:, 0] + boxes[:, 1]) / 2
    out = np.linalg.norm(centre[:, :2] - com[:2], axis=1)
    thin = (size[:, :2].min(axis=1) < HANDLE_THIN_M) & (out > HANDLE_OUT_M)
    if thin.sum() < 2:
        return None
    far = int(np.argmax(np.where(thin, out, -1.0)))
    side = centre[far, :2] - com[:2]
    parts = boxes[thin & ((centre[:, :2] - com[:2]) @ side > 0)]
    lo, hi = parts[:, 0].min(axis=0), parts[:, 1].max(axis=0)
    thin_axis = int(np.argmin((hi - lo)[:2]))  # fingers close along it
    d = rot[:, thin_axis]  # ... in world
    # closing_axis(yaw) = (-sin, cos), the same for yaw + pi: yaw in (-pi/2, pi/2] as for an
    # unturned pot (0 or pi/2), widened by YAW_BAND so a pot turned a few degrees the other
    # way is not grasped with the hand turned half round
    yaw = closing_yaw(d)
    lo_yaw = -np.pi / 2 + YAW_BAND
    yaw = yaw - np.pi if yaw > lo_yaw + np.pi else yaw + np.pi if yaw <= lo_yaw else yaw
    pos = body + rot @ ((lo + hi) / 2)
    return Grasp(pos=pos, yaw=yaw, rim=False)


def whole_grasp(scene: Scene, obj: str, dest: np.ndarray | None, choice: int) -> Grasp | None:
    """Around the object's middle, across its narrowest closing direction that fits between
    the fingers (little wrist turn preferred); None when no direction fits."""
    box = scene.box(obj)
    corners = scene.env.object_corners(obj)
    centre = box.centre
    h = box.size[2]
    floor = box.lo[2] + TABLE_MARGIN
    widths = [(float(np.ptp(corners[:, :2] @ closing_axis(y)[:2])), y) for y in YAWS]
    fitting = []
    slab = is_upright_slab(scene, obj)
    for w, yaw in widths:
        if w >= MAX_SPAN:
            continue
        mid = corners[:, :2] @ closing_axis(yaw)[:2]
        z = box.lo[2] + (min(max(0.5 * h, 0.015), h - 0.02) if h > 0.03 else 0.5 * h)
        if slab:
            z = box.hi[2] - SLAB_GRIP_BELOW_TOP
        pos = np.array([centre[0], centre[1], max(z, floor)])
        # centre between the extreme faces along the closing axis
        pos[:2] += closing_axis(yaw)[:2] * ((mid.max() + mid.min()) / 2 - centre[:2] @ closing_axis(yaw)[:2])
        # a long object lying on its side (a toppled bottle): grasp it at its centre of
        # mass along its length, or it pivots out of the fingers when lifted
        along = np.array([closing_axis(yaw)[1], -closing_axis(yaw)[0]])
        if float(np.ptp(corners[:, :2] @ along)) > LONG_M:
            com = scene.env.object_com(obj)[:2]
            pos[:2] += along * ((com - pos[:2]) @ along)
        # a neighbour under the palm's ends (it reaches ~10 cm along the closing axis)
        # would stop the descent: such yaws lose
        block = blocked_depth(scene, pos, yaw, box.hi[2], skip_tips=True)
        fitting.append((w + 0.02 * abs(yaw) + 10 * block, len(fitting), Grasp(pos=pos, yaw=float(yaw), rim=False)))
    if fitting:
        return sorted(fitting, key=lambda f: f[:2])[choice % len(fitting)][2]
    return None


def tall_handle_grasp(scene: Scene, obj: str, dest: np.ndarray | None, choice: int) -> Grasp | None:
    """A moka pot's handle (`handle_grasp`) on even choices; its rim on odd ones (a retry)."""
    handle = handle_grasp(scene, obj)
    return handle if handle is not None and choice % 2 == 0 else None


def pan_grasp(scene: Scene, obj: str, dest: np.ndarray | None, choice: int) -> Grasp | None:
    """A frying pan: always by its handle (pan_handle.py)."""
    return pan_handle_grasp(scene, obj)


def leaning(scene: Scene, obj: str) -> bool:
    """`obj` rests tilted on something, its own up axis LEAN_MIN to LEAN_MAX from vertical
    (a bowl on a drawer's front wall or half on its side wall)."""
    up = scene.env.object_frame(obj)[1][:, 2]
    return bool(LEAN_MIN < np.arccos(np.clip(up[2], -1.0, 1.0)) < LEAN_MAX)


@dataclass(frozen=True)
class Rim:
    """A tilted round object's rim, read in the object's own frame."""

    pos: np.ndarray  # body origin (world)
    rot: np.ndarray  # body rotation (3, 3)
    top: float  # the rim's height, own frame
    height: float  # the object's own height (its box along its own up axis)
    mid: np.ndarray  # the rim's centre (xy, own frame)
    radius: float
    rise: np.ndarray  # the rim plane's steepest way up (xy, own frame)

    def highest(self, inset: float) -> np.ndarray:
        """The rim's highest point, `inset` in from its outer edge (world)."""
        return self.pos + self.rot @ np.array([*(self.mid + self.rise * (self.radius - inset)), self.top])


def rim(scene: Scene, obj: str) -> Rim:
    pos, rot = scene.env.object_frame(obj)
    local = (scene.env.object_corners(obj) - pos) @ rot
    lo, hi = local.min(axis=0), local.max(axis=0)
    return Rim(pos=pos, rot=rot, top=float(hi[2]), height=float(hi[2] - lo[2]), mid=(hi[:2] + lo[:2]) / 2,
               radius=float(np.min(hi[:2] - lo[:2])) / 2, rise=rot[2, :2] / np.linalg.norm(rot[2, :2]))


def side_rim(scene: Scene, obj: str, side: int) -> Grasp:
    """A leaning object's rim wall where it stands vertical: a quarter turn round the rim
    from its highest point (`side` 0 or 1: which way), the fingers closing across it. At the
    highest point the wall's outside faces up and the outer finger came down on it: the bowl
    was pushed down and slipped out (measured: a bowl leaning 46 degrees in the bottom
    drawer); a level rim grasp aims under the box top, over the lower rim, into the air."""
    r = rim(scene, obj)
    across = np.array([-r.rise[1], r.rise[0]]) * (1 if side % 2 == 0 else -1)
    point = r.pos + r.rot @ np.array([*(r.mid + across * (r.radius - RIM_INSET)), r.top])
    point[2] -= RIM_DEPTH
    out = r.rot[:2, :2] @ across
    theta = float(np.arctan2(out[1], out[0]))
    # the fingers close across the wall (along `out`), as rim_grasp's do
    return Grasp(pos=point, yaw=float(theta % np.pi - np.pi / 2), rim=True)


def rim_grasp(scene: Scene, obj: str, dest: np.ndarray | None, choice: int) -> Grasp:
    """By the rim wall: the radial direction whose outer finger lands clear (and, with
    `dest`, whose hand fits at the destination too); a leaning object first where its wall
    stands vertical (`side_rim`, either side)."""
    if leaning(scene, obj):
        if choice < 2:
            top = scene.box(obj).hi[2]
            sides = [side_rim(scene, obj, k) for k in (0, 1)]
            # the side a cabinet overhangs (a drawer's back) loses, as for a level rim
            sides.sort(key=lambda g: blocked_depth(scene, g.pos, g.yaw, top) * 10 + 10 * overreach(scene.env, g.pos))
            return sides[choice]
        choice -= 2
    box = scene.box(obj)
    corners = scene.env.object_corners(obj)
    centre = box.centre
    floor = box.lo[2] + TABLE_MARGIN
    ranked = []
    for theta in np.linspace(-np.pi, np.pi, 16, endpoint=False):
        u = np.array([np.cos(theta), np.sin(theta), 0.0])
        reach = float(np.max((corners - centre) @ u))
        p = centre + u * (reach - RIM_INSET)
        p[2] = max(box.hi[2] - RIM_DEPTH, floor)
        yaw = (theta - np.pi / 2 + np.pi / 2) % np.pi - np.pi / 2
        block = blocked_depth(scene, p, yaw, box.hi[2])
        if dest is not None:
            body = scene.env.object_pose(obj)[0]
            there = p - body
            there[:2] += dest[:2]
            there[2] = p[2] - box.lo[2] + dest[2] + 0.015
            block += blocked_depth(scene, there, yaw, there[2])
        # at the edge of the workspace the near rim keeps the elbow bent (see reach.py)
        score = block * 10 + 0.01 * abs(yaw) + 10 * overreach(scene.env, p)
        ranked.append((score, len(ranked), Grasp(pos=p, yaw=float(yaw), rim=True)))
    ranked.sort(key=lambda r: r[:2])
    return ranked[choice % len(ranked)][2]


# the grasp strategies, asked in order: the first that gives a grasp is taken (the last always does)
GRASPS: tuple[Callable[[Scene, str, np.ndarray | None, int], Grasp | None], ...] = (
    whole_grasp, tall_handle_grasp, pan_grasp, rim_grasp)


def plan_grasp(scene: Scene, obj: str, dest: np.ndarray | None = None, choice: int = 0) -> Grasp:
    """`dest` (x, y, support top) is where the object's body goes next: the hand must fit
    there too, so rim sides that would put the hand into a wall at the target lose.
    `choice` k > 0 takes the k-th best candidate instead of the best (a retry after a
    failed grasp tries another yaw or rim side, not the same one again)."""
    for strategy in GRASPS:
        g = strategy(scene, obj, dest, choice)
        if g is not None:
            return g
    raise AssertionError("rim_grasp always answers")
