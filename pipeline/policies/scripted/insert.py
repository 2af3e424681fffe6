"""Skill: put an object into a roofed container through its door opening (a mug into a
microwave), horizontally.

A top-down hand cannot reach under the microwave's roof: its palm sits 4-10 cm above the
grip site. So the hand is tilted to point into the opening and grasps the object by its
handle (a mug's vertical bar, thin across the hand's closing axis) from the side that
faces the opening; only the fingers then pass the door plane. Plan: tilt behind the
handle, advance, grip, lift, carry to in front of the opening at the container's floor
height + margin, move in along the opening's inward direction until the whole object is
behind the door plane, lower, release, back out the same way, untilt. Closing the door is
the planner's next conjunct.

Inputs: a `Ctx` and an `in` conjunct whose region lies inside a fixture with a hinged door
and a roof over the region (`roofed`). One attempt per call; it returns early (no motion)
when the object has no handle facing the opening, so the caller can fall back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted import articulated
from pipeline.policies.scripted.primitives import Grip
from pipeline.policies.scripted.skills import Ctx, Plan, free_hand, grasp, place_at, travel

HANDLE_OUT_M = 0.06  # boxes of a mug this far (xy) from its centre of mass form the handle
FLOOR_MARGIN = 0.025  # object's bottom above the container floor while moving in
DOOR_MARGIN = 0.014  # object's nearest point behind the door plane
BACK_MARGIN = 0.012  # object's farthest point in front of the back wall
STANDOFF_M = 0.07  # grip site behind the handle before advancing onto it
MAX_TURN = np.radians(50)  # handle direction may differ this much from facing the opening


@dataclass(frozen=True)
class Opening:
    inward: np.ndarray  # unit horizontal vector into the container
    front: float  # door plane, as a coordinate along `inward`
    back: float  # back wall's inner face along `inward`
    floor: float  # top of the container floor
    ceiling: float  # underside of its roof
    side: tuple[float, float]  # free span across `inward` (inner faces of the side walls)


def _door(env, region: str) -> str | None:
    owner = articulated.openable(env, region)
    if owner is None or env.is_region(owner):
        return None
    joint = articulated.part_joint(env, owner)
    return joint if joint is not None and env.joint_frame(joint)["kind"] == "hinge" else None


def opening(env, region: str) -> Opening | None:
    """The door opening of the container holding `region`, or None when the region is not
    under a roof behind a hinged door."""
    joint = _door(env, region)
    if joint is None:
        return None
    r = env.region(region)
    fr = env.joint_frame(joint)
    # the door's closed pose: its boxes' centre turned back about the hinge by -qpos
    door = env.joint_part_boxes(joint)
    c = (door[:, 0] + door[:, 1]).mean(axis=0)[:2] / 2 - fr["anchor"][:2]
    a = -fr["qpos"] * float(np.sign(fr["axis"][2]))
    closed = fr["anchor"][:2] + [c[0] * np.cos(a) - c[1] * np.sin(a), c[0] * np.sin(a) + c[1] * np.cos(a)]
    d = r["pos"][:2] - closed
    k = int(np.argmax(np.abs(d)))
    inward = np.zeros(3)
    inward[k] = np.sign(d[k])
    door_ids = {tuple(np.round(b.ravel(), 6)) for b in door}
    body = [b for b in env.object_boxes(r["parent"]) if tuple(np.round(b.ravel(), 6)) not in door_ids]
    across = 1 - k
    at = r["pos"]
    inside = [b for b in body if b[0, across] <= at[across] <= b[1, across] and b[0, k] <= at[k] <= b[1, k]]
    floor = max((b[1, 2] for b in inside if b[1, 2] <= at[2]), default=None)
    ceiling = min((b[0, 2] for b in inside if b[0, 2] >= at[2]), default=None)
    if floor is None or ceiling is None:
        return None  # no roof over the region: top-down placing works
    s = inward[k]
    mid = (floor + ceiling) / 2
    walls = [b for b in body if b[0, 2] < mid < b[1, 2]]
    # the back wall: spans the region across, lies beyond its centre along inward
    backs = [(b[0, k] if s > 0 else -b[1, k]) for b in walls
             if b[0, across] <= at[across] <= b[1, across] and s * ((b[0, k] + b[1, k]) / 2 - at[k]) > 0]
    # side walls: overlap the region's depth, on either side of it across
    lo = max((b[1, across] for b in walls if b[1, across] < at[across] and b[0, k] < at[k] < b[1, k]), default=-np.inf)
    hi = min((b[0, across] for b in walls if b[0, across] > at[across] and b[0, k] < at[k] < b[1, k]), default=np.inf)
    # the door plane: the near face of the floor and roof (a control panel may stand out)
    front_faces = [(b[0, k] if s > 0 else -b[1, k]) for b in inside]
    return Opening(
        inward=inward,
        front=float(min(front_faces)),
        back=float(min(backs)) if backs else float(s * at[k] + 0.1),
        floor=float(floor),
        ceiling=float(ceiling),
        side=(float(lo), float(hi)),
    )


def roofed(env, conjunct: tuple[str, ...]) -> bool:
    """An `in` conjunct whose region can only be reached through a door opening."""
    return conjunct[0] == "in" and env.is_region(conjunct[2]) and opening(env, conjunct[2]) is not None


@dataclass(frozen=True)
class HandleGrasp:
    pos: np.ndarray  # grip site on the handle bar
    out: np.ndarray  # unit horizontal direction from the body to the handle
    reach: float  # object's extent from its body origin away from the handle (along -out)
    back: float  # handle's extent from the body origin along `out`


def handle_grasp(s, obj: str) -> HandleGrasp | None:
    """The vertical bar of an upright object's side handle (a mug's), or None."""
    env = s.env
    com = env.object_com(obj)
    body = env.object_pose(obj)[0]
    boxes = env.object_boxes(obj)
    centre = (boxes[:, 0] + boxes[:, 1]) / 2
    out_d = np.linalg.norm(centre[:, :2] - com[:2], axis=1)
    handle = boxes[out_d > HANDLE_OUT_M]
    if len(handle) == 0:
        return None
    far = int(np.argmax(out_d))
    out = np.array([*(centre[far, :2] - com[:2]), 0.0])
    out /= np.linalg.norm(out)
    # the bar: the handle box whose centre lies outermost along `out`
    bar = handle[int(np.argmax(((handle[:, 0] + handle[:, 1]) / 2) @ out))]
    pos = (bar[0] + bar[1]) / 2
    pos[2] = bar[1, 2] - 0.014  # high on the bar: the arm cannot point the hand level much lower
    corners = env.object_corners(obj)
    along = (corners - body) @ out
    return HandleGrasp(pos=pos, out=out, reach=float(-along.min()), back=float(along.max()))


def can_insert(s, conjunct: tuple[str, ...]) -> bool:
    """The conjunct needs an insertion and the object offers a handle facing the opening."""
    if not roofed(s.env, conjunct) or conjunct[1] not in s.env.object_names:
        return False
    h = handle_grasp(s, conjunct[1])
    return h is not None and float(-h.out @ opening(s.env, conjunct[2]).inward) >= np.cos(MAX_TURN)


def hand_zone(s, conjunct: tuple[str, ...]) -> np.ndarray:
    """(2, 3) world box the tilted hand takes while it grips the handle: its palm is ~21 cm
    wide across the approach and reaches 2.6-12.4 cm behind the grip site, and the wrist
    (link 6) comes down ~20 cm further back, low over the table."""
    h = handle_grasp(s, conjunct[1])
    a = opening(s.env, conjunct[2]).inward
    across = np.array([-a[1], a[0], 0.0])
    pts = [h.pos - a * d + across * w for d in (0.0, 0.32) for w in (-0.115, 0.115)]
    lo, hi = np.min(pts, axis=0), np.max(pts, axis=0)
    return np.array([[lo[0], lo[1], h.pos[2] - 0.045], [hi[0], hi[1], h.pos[2] + 0.2]])


def blockers(s, conjunct: tuple[str, ...]) -> list[str]:
    """Other objects standing where the hand goes to grip the handle: moved aside first."""
    zone = hand_zone(s, conjunct)
    out = []
    for o in s.env.object_names:
        if o == conjunct[1]:
            continue
        b = s.box(o)
        if np.all(b.lo <= zone[1]) and np.all(b.hi >= zone[0]):
            out.append(o)
    return out


def clear_spot(s, obj: str, zone: np.ndarray) -> np.ndarray | None:
    """The nearest table spot (body xy) for `obj` where its footprint keeps 1 cm off `zone`
    and off everything else standing on the table (the general put-aside spots lie in
    front of the robot, often all within the wide hand's zone)."""
    from pipeline.policies.scripted.recovery import checks

    box = s.box(obj)
    body = s.env.object_pose(obj)[0]
    lo, hi = box.lo[:2] - body[:2] - 0.01, box.hi[:2] - body[:2] + 0.01
    table = s.table_height()
    boxes = [b for _, b in s.obstacle_boxes({obj}) if b[1, 2] > table + 0.005] + [zone]
    base = checks.robot_base(s)[:2]
    best = None
    for dx in np.arange(-0.24, 0.241, 0.02):
        for dy in np.arange(-0.24, 0.241, 0.02):
            xy = body[:2] + [dx, dy]
            rel = xy - base
            if np.any(rel < checks.COMFORT_XY[0] + 0.1) or np.any(rel > checks.COMFORT_XY[1] - 0.1):
                continue
            if any(np.all(xy + lo <= b[1, :2]) and np.all(b[0, :2] <= xy + hi) for b in boxes):
                continue
            # off the arm's way: the forearm comes low from the robot base to the zone
            c = (zone[0, :2] + zone[1, :2]) / 2
            u = np.clip((xy - base) @ (c - base) / float((c - base) @ (c - base)), 0.0, 1.0)
            if np.linalg.norm(xy - (base + u * (c - base))) < 0.15:
                continue
            d = float(np.hypot(dx, dy))
            if best is None or d < best[0]:
                best = (d, xy)
    return None if best is None else best[1]


def _yaw_across(approach: np.ndarray) -> float:
    """Hand yaw whose closing axis is horizontal and across `approach` (fingers pinch a
    vertical bar); `hand_orientation` then tilts it to point along `approach`."""
    return float(np.arctan2(approach[1], approach[0]) - np.pi)


def insert(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    """One attempt: grasp `obj` by its handle with the hand pointing into the opening,
    carry it in horizontally, release, back out."""
    _, obj, region = conjunct
    s, env = ctx.scene, ctx.scene.env
    op = opening(env, region)
    if op is None:
        return
    h = handle_grasp(s, obj)
    if h is None or float(-h.out @ op.inward) < np.cos(MAX_TURN):
        return  # callers check `can_insert` first
    # recorded as a pick-and-place attempt (the truth log judges it from the trace)
    ctx.begin("pick_place", conjunct, obj, region)
    yield from free_hand(ctx)
    a = op.inward
    yaw = _yaw_across(a)
    offset = ctx.noise.grasp_offset() * [0.3, 0.3, 0.3]
    ctx.note(grasp_offset=offset)
    grip = h.pos + offset
    ready = grip - a * STANDOFF_M
    lift_z = s.path_clearance(s.eef(), ready, 0.08, {obj}) + 0.09
    # from a far-out arm pose (after putting something aside) the arm cannot then point
    # the hand level low enough: pass over the home pose first (its null-space posture)
    from pipeline.policies.scripted.recovery import checks

    home = checks.robot_base(s)[:2] + checks.HOME_XY
    if np.linalg.norm(s.eef()[:2] - home) > 0.15:
        yield from travel(ctx, np.array([home[0], home[1], lift_z]), 0.0, -1.0, lift_z)
    yield from travel(ctx, ready + [0, 0, 0.08], 0.0, -1.0, lift_z)
    ctx.yaw_hold, ctx.approach_hold = yaw, a
    yield ctx.move(ready + [0, 0, 0.04], yaw=yaw, approach=a, tol=0.015, rot_tol=0.12, max_steps=60, label="tilt")
    yield ctx.move(ready, yaw=yaw, approach=a, tol=0.01, max_steps=30, label="lower_behind")
    yield ctx.move(grip, yaw=yaw, approach=a, speed=0.6, tol=0.007, max_steps=60, label="descend")
    yield Grip(1.0, ctx.close_steps + 4, label="grip_handle")
    body = env.object_pose(obj)[0]
    hold = s.eef() - body  # grip site relative to the body origin, kept while carrying
    bottom = s.eef()[2] - s.box(obj).lo[2]
    # where the body goes: across, the middle of the free span; along, as deep as the back
    # wall allows but with the handle behind the door plane
    k = int(np.argmax(np.abs(a)))
    across = 1 - k
    r = env.region(region)["pos"]
    side_r = float(np.max(np.abs((env.object_corners(obj) - body)[:, across])))
    lo, hi = op.side[0] + side_r + 0.01, op.side[1] - side_r - 0.01
    dest = body.copy()
    dest[across] = float(np.clip(r[across], lo, hi)) if lo < hi else (op.side[0] + op.side[1]) / 2
    depth_max = op.back - BACK_MARGIN - h.reach
    depth_min = op.front + DOOR_MARGIN + h.back
    depth = min(max(float(a[k] * r[k]), depth_min), depth_max)
    dest[k] = a[k] * depth
    carry_z = op.floor + FLOOR_MARGIN + bottom
    outside = dest.copy()
    outside[k] = a[k] * (op.front - 0.02 - h.reach)
    yield ctx.move(s.eef() + [0, 0, 0.05], gripper=1.0, yaw=yaw, approach=a, speed=0.5, tol=0.015,
                   max_steps=30, label="pick_lift")
    if s.holding_any() != obj:
        ctx.events.append(f"missed_grasp:{obj}")
        if ctx.truth is not None:
            ctx.truth.end_hand(obj, False)
        return
    # over to in front of the opening, high enough to clear what lies between
    pre = outside + hold
    pre[2] = carry_z
    clear = s.path_clearance(s.box(obj).centre, pre, 0.06, {obj}) + 0.02 + bottom
    z = max(carry_z, min(clear, carry_z + 0.1), s.eef()[2])
    yield ctx.move([s.eef()[0], s.eef()[1], z], gripper=1.0, yaw=yaw, approach=a, tol=0.015, max_steps=40, label="lift")
    yield ctx.move([pre[0], pre[1], z], gripper=1.0, yaw=yaw, approach=a, tol=0.012, max_steps=80, label="transport")
    yield ctx.move(pre, gripper=1.0, yaw=yaw, approach=a, speed=0.5, tol=0.008, max_steps=40, label="align")
    goal = dest + hold
    goal[2] = carry_z
    yield ctx.move(goal, gripper=1.0, yaw=yaw, approach=a, speed=0.7, tol=0.01, max_steps=50, label="move_in")
    if s.holding_any() != obj:
        ctx.events.append(f"dropped:{obj}")
    yield ctx.move(goal - [0, 0, FLOOR_MARGIN - 0.004], gripper=1.0, yaw=yaw, approach=a, speed=0.4, tol=0.006,
                   max_steps=15, label="lower")
    yield Grip(-1.0, ctx.open_steps + 4, label="open")
    yield ctx.move(s.eef() - a * (STANDOFF_M + 0.02), yaw=yaw, approach=a, speed=0.5, tol=0.015, max_steps=50,
                   label="back_out")
    ctx.yaw_hold, ctx.approach_hold = 0.0, None
    yield ctx.move(s.eef() + [0, 0, 0.08], tol=0.02, rot_tol=0.2, max_steps=25, label="untilt")
    if ctx.truth is not None:
        ctx.truth.end_hand(obj, s.satisfied(conjunct))


def clear_zone(ctx: Ctx, conjunct: tuple[str, ...], other: str, attempt: int = 0) -> Plan:
    """Move `other` out of the hand's zone for `conjunct` to the nearest clear spot."""
    s = ctx.scene
    if s.holding_any() != other:
        yield from free_hand(ctx)
        yield from grasp(ctx, other, None, choice=attempt, hover_m=0.08 + 0.03 * min(attempt, 2))
        if s.holding_any() != other:
            return
    zone = hand_zone(s, conjunct)
    spot = clear_spot(s, other, zone)
    if spot is None:
        spot = s.env.object_pose(other)[0][:2] - opening(s.env, conjunct[2]).inward[:2] * 0.08
    yield from place_at(ctx, other, spot)
