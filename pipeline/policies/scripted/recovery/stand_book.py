"""Skill: pick up a book that leans or lies tilted (not standing on its bottom edge) so that
it hangs upright in the hand, ready for the slot skill (slot.py).

Input: a `Ctx` and an object `obj` that is a book (`book_axes`: a thin slab whose body
origin lies on one of its edges, its bottom: LIBERO's `In` tests that origin) whose up axis
is tilted from vertical. Output: primitives that
1. tilt the open hand so it points down the book's up axis, fingers closing across its
   thickness, above the middle of its top edge;
2. go down along that axis and close on the top edge (as deep as a standing book's grasp,
   `grasps.SLAB_GRIP_BELOW_TOP`);
3. lift, and turn the hand back to pointing straight down: the book turns with it and hangs
   upright, held near its top edge like a standing book grasped from above (a few degrees
   off, as it pivots in the fingers: it is let stop swinging, and `slot_size` gives the
   slot skill the book's own size to fit rather than its widened footprint).
A top-down grasp cannot hold such a book: every horizontal width of a leaning book is wider
than the open fingers, and a rim grasp slips off its faces (measured: 4 of 4 missed).
The hand turns at most `MAX_TILT` from pointing down (a hand pointing level, low over the
table, is out of the wrist's range: measured 25 deg short). A book tilted further (lying on
its side, or standing on its top edge, upside down: its origin then cannot get into a
compartment) is turned by a quarter at a time: `quarter_turn` holds it by a top corner with
the hand pitched 45 deg along the book's plane (30 deg where the arm then reaches the end of
the turn, `_turn_pitch`), lifts it, pitches the hand the rest of the quarter the other way,
sets it down where it was and lets go. Upside down takes two quarters, then the book
stands and is grasped from above as usual. A book whose top leans toward the robot's base,
its faces standing, is turned the same way by its whole tilt (`turn_first`): the hand along
its axis is out of reach there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted.grasps import SLAB_GRIP_BELOW_TOP, SLAB_RATIO, SLAB_THIN_M

from pipeline.policies.scripted.hand import FINGER_REACH, closing_yaw
from pipeline.policies.scripted.motion import HAND_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.primitives import Grip, axis_angle_matrix, hand_orientation, rotation_error
from pipeline.policies.scripted.recovery.checks import toward_base
from pipeline.policies.scripted.scene import Scene

UPRIGHT_DEG = 20.0  # up axis within this of vertical: standing, grasped from above as usual
MAX_TILT = np.radians(75.0)  # most the hand is tilted from pointing down (further: out of reach)
# faces' normal more vertical than this (sine of its elevation): lying on its face. A book
# lying across a compartment or against a mug with its faces 30-45 deg from level (normal
# 0.74-0.86) leans: it was taken for lying flat and got top-down grasps, which slid off its
# faces four times (measured: tune26, STUDY_SCENE2's front and STUDY_SCENE3's right compartments)
FACE_UP = 0.9
BOTTOM_FRAC = 0.1  # the origin lies within this fraction of the height from one end: a book
BACK_OFF_M = 0.09  # grip site this far up the book's axis from the grasp before going in
LIFT_M = 0.12  # lift after closing, before the hand turns
SETTLE_STEPS = 10  # the book swings on in the fingers this long after the hand stopped turning
# ... and may swing on after it (measured: 0.4 -> 5.1 -> 0.1 deg over 13 steps), then hang a
# few degrees off upright (steady at 3.6 deg). The slot skill measures the footprint it fits:
# mid-swing it varies from step to step, so wait until the swing stops (under SWING_DEG in
# SWING_STEPS, at most SWING_MAX_STEPS), and see `slot_size` for the steady tilt
SWING_DEG = 0.3
SWING_STEPS = 4
SWING_MAX_STEPS = 40
TILT_STEPS = 60
REACH_TOL = 0.1  # radians off the tilted orientation after TILT_STEPS: out of reach
STEEP = np.radians(65.0)  # hand tilts beyond this are made TURN_ABOVE_M above the start point
TURN_ABOVE_M = 0.15
TURN_CLEAR_M = 0.05  # lowest corner above the table while the book turns
PITCH = np.radians(45.0)  # hand pitch either way for a quarter turn
# ... or less at the grasp where the turn then stays in reach (`_turn_pitch`)
NEAR_PITCH = np.radians(30.0)
TURN_REACH_RAD = 0.15  # `SimEnv.ik_reach` this near the turned hand: in reach
GAIN_TIE = 0.05  # two ways of turning that bring the up axis this near (its height) are alike
FACES_STAND = 0.3  # faces' normal more level than this (sine of its elevation): it turns in its plane
LEANS_TO_BASE = 0.5  # its up axis's level part this near (cosine) the way to the robot's base
LEAN_OVERSHOOT = np.radians(10.0)  # turned past its tilt by this (it lags the hand: 17-29 deg measured)
LAG_TOL = np.radians(5.0)  # ... and on while it lags short of upright by more than this
STRAIGHTEN_TRIES = 2
CORNER_DEPTH_M = 0.03  # grip site inside the corner along the hand's axis
PUT_DOWN_GAP = 0.008  # book's lowest point above the table when it is let go
# the tilted hand at its grip: points along it (back from the grip site, out along the closing
# axis) that must be clear of other objects' boxes padded by EDGE_ROOM_M (a finger's half width)
PALM_POINTS_M = ((0.03, FINGER_REACH), (0.07, 0.0), (0.07, 0.05))
EDGE_ROOM_M = 0.01
LEVEL_TOL = 0.3  # radians: the hand this near pointing down after a turn (`back_out` calls 25 deg awkward)
RETREAT_PULL_M = 0.08  # toward the base as the hand rises after a set-down, when it points there
TOWARD_BASE = 0.3  # ... its level part this long in the base's direction or longer


@dataclass(frozen=True)
class BookAxes:
    up: np.ndarray  # world unit vector from the bottom edge (body origin) to the top edge
    thin: np.ndarray  # world unit normal of its faces
    top_mid: np.ndarray  # world point: middle of the top edge, mid-thickness
    long: np.ndarray  # world unit vector along its bottom edge
    ends: tuple[np.ndarray, np.ndarray]  # world points: middles of the two ends along `long`

    @property
    def length(self) -> float:
        """Its size along `long` (its bottom edge)."""
        return float(np.linalg.norm(self.ends[1] - self.ends[0]))

    @property
    def height(self) -> float:
        """Its size along `up`: twice the top edge's distance from its centre."""
        return 2 * float(np.linalg.norm(self.top_mid - (self.ends[0] + self.ends[1]) / 2))


def book_axes(scene: Scene, obj: str) -> BookAxes | None:
    """A book's axes from its collision boxes in its body frame, or None when `obj` is not
    book-shaped (a thin slab, long, whose body origin lies at one end of a long side)."""
    pos, rot = scene.env.object_frame(obj)
    local = (scene.env.object_corners(obj) - pos) @ rot  # corners in the body frame
    lo, hi = local.min(axis=0), local.max(axis=0)
    size = hi - lo
    t = int(np.argmin(size))
    others = [i for i in range(3) if i != t]
    if size[t] >= SLAB_THIN_M or min(size[others]) < SLAB_RATIO * size[t]:
        return None
    # the up axis: the one along which the origin sits at an end (a book's bottom)
    ends = {i: min(abs(lo[i]), abs(hi[i])) / size[i] for i in others}
    u = min(ends, key=ends.get)
    if ends[u] > BOTTOM_FRAC:
        return None
    sign = 1.0 if abs(lo[u]) < abs(hi[u]) else -1.0
    centre = (lo + hi) / 2
    mid = centre.copy()
    mid[u] = hi[u] if sign > 0 else lo[u]
    w = next(i for i in others if i != u)
    a, b = centre.copy(), centre.copy()
    a[w], b[w] = lo[w], hi[w]
    return BookAxes(up=rot[:, u] * sign, thin=rot[:, t], top_mid=pos + rot @ mid, long=rot[:, w],
                    ends=(pos + rot @ a, pos + rot @ b))


def stand_tilt(scene: Scene, obj: str) -> BookAxes | None:
    """The book's axes when it is a book tilted out of standing (tilt over UPRIGHT_DEG);
    None otherwise. `too_steep` says whether it must first be turned by a quarter."""
    ax = book_axes(scene, obj)
    if ax is None or abs(float(ax.thin[2])) > FACE_UP:
        return None  # lying on its face: no edge a hand can close across is up
    return ax if _tilt(ax.up) > np.radians(UPRIGHT_DEG) else None


def too_steep(ax: BookAxes) -> bool:
    return _tilt(ax.up) > MAX_TILT


def turn_first(scene: Scene, ax: BookAxes) -> tuple[float, float, bool] | None:
    """How to turn a tilted book in its own plane before it is grasped, as `quarter_turn`'s
    (angle, grasp pitch, upright), or None when `stand_up` takes it as it lies. Too steep:
    a quarter, the hand pitched half of it either way. Its faces standing and its top
    leaning toward the robot's base: the hand along its axis would point away from the base
    close to it, and the elbow folds to its limit short of the top edge (measured: joint 4
    at -3.07 rad, 9 cm off; two tuning scenes, both timeouts, while the four leaning away
    were certified). It is grasped with the hand pointing down and turned by its tilt and
    LEAN_OVERSHOOT, the hand pitching toward the base, and on until it stands (it lags the
    hand as it pivots in the fingers)."""
    if too_steep(ax):
        return 2 * PITCH, _turn_pitch(scene, ax), False
    to_base = (scene.env.robot_base() - ax.top_mid)[:2]
    toward = float(ax.up[:2] @ to_base) / max(float(np.linalg.norm(to_base)), 1e-6)
    if abs(float(ax.thin[2])) < FACES_STAND and toward > LEANS_TO_BASE:
        return _tilt(ax.up) + LEAN_OVERSHOOT, 0.0, True
    return None


def _turn_pitch(scene: Scene, ax: BookAxes) -> float:
    """The hand's pitch at the grasp of a quarter turn: NEAR_PITCH where the arm, following
    the grasp, the lift and the turn (`SimEnv.ik_reach` chained), ends within TURN_REACH_RAD
    of the turned hand; else PITCH. Pitched 45 deg at a corner far from the base, the elbow
    went straight against its limit: the turn crept on for 95 steps, the hand drifted 12 cm
    out and 7 cm up, and let go of the book 17 cm over the table (measured: two of
    `book_poses.py`'s books on a side, timeouts). Pitched 30 deg, the hand has to pitch 60
    deg the other way after the turn, out of the wrist's reach in other places (measured:
    the turns that stalled ended 0.22-0.33 rad off, those that went 0-0.12)."""
    grip, a1, a2 = _corner_grip(scene, ax, 2 * PITCH, NEAR_PITCH)
    yaw, approach = tilted_grasp(_held(ax, grip, a1))
    up = grip + [0.0, 0.0, _turn_lift(scene, ax, grip)]
    env = scene.env
    joints, *_ = env.ik_reach(grip, hand_orientation(yaw, approach))
    joints, *_ = env.ik_reach(up, hand_orientation(yaw, approach), start=joints)
    _, _, off_rad = env.ik_reach(up, hand_orientation(yaw, a2), start=joints)
    return NEAR_PITCH if off_rad <= TURN_REACH_RAD else PITCH


def _held(ax: BookAxes, grip: np.ndarray, a1: np.ndarray) -> BookAxes:
    """The book's axes as `_edge_grasp_turn` sees them for a quarter turn's corner grasp at
    `grip` with the hand pointing along `a1`: the corner is its top."""
    return BookAxes(up=-a1, thin=ax.thin, top_mid=grip + (-a1) * SLAB_GRIP_BELOW_TOP,
                    long=np.cross(ax.thin, ax.up), ends=ax.ends)


def _turn_lift(s: Scene, ax: BookAxes, grip: np.ndarray) -> float:
    """How high a quarter turn lifts the book gripped at `grip` before it turns: held by a
    corner, it swings through up to its diagonal below the fingers, that far clear of the
    table."""
    reach = max(float(np.linalg.norm(c - grip)) for c in _plane_corners(ax))
    return max(reach + TURN_CLEAR_M - (grip[2] - s.table_height()), 0.04)


def _tilt(up: np.ndarray) -> float:
    return float(np.arccos(np.clip(up[2], -1.0, 1.0)))


def tilted_grasp(ax: BookAxes) -> tuple[float, np.ndarray]:
    """(yaw, approach) of a hand pointing along -up (the `up` given), closing
    across the faces. `hand_orientation(yaw, approach)` is the top-down hand at `yaw` turned
    about the horizontal axis cross(-z, approach); its closing axis must then be `thin`."""
    a = -ax.up
    down = np.array([0.0, 0.0, -1.0])
    h = np.cross(down, a)
    angle = float(np.arccos(np.clip(a @ down, -1.0, 1.0)))
    turn = axis_angle_matrix(h, angle) if np.linalg.norm(h) > 1e-6 else np.eye(3)
    # the fingers are symmetric: of the two ways round, the one nearer the wrist's middle.
    # Turning back to top-down undoes `turn`: the closing axis returns to c0, the yaw stays
    yaw = min((closing_yaw(turn.T @ (sg * ax.thin)) for sg in (1.0, -1.0)), key=abs)
    return yaw, a


def stand_up(ctx: Ctx, obj: str, ax: BookAxes) -> Plan:
    yield from _edge_grasp_turn(ctx, obj, ax)
    # the book swings on in the fingers for a few steps after the hand stopped turning; the
    # slot skill measures its footprint next
    yield Grip(1.0, SETTLE_STEPS, label="settle")
    was = _off_upright(ctx.scene, obj)
    for _ in range(SWING_MAX_STEPS // SWING_STEPS):
        yield Grip(1.0, SWING_STEPS, label="settle")
        now = _off_upright(ctx.scene, obj)
        if abs(now - was) < np.radians(SWING_DEG):
            break
        was = now


def slot_size(s: Scene, obj: str) -> tuple[float, float] | None:
    """(length, thickness) of a book held upright, for the slot skill to fit instead of its
    footprint. It hangs a few degrees off upright in the fingers (pivoting there: steady
    at 3.6 deg), which widens the footprint of an 11.3 cm book past the 11.6 cm the slot
    skill fits into a 12.4 cm compartment; put in anyway, it straightens as its bottom meets
    the floor (measured: STUDY_SCENE2 and STUDY_SCENE3's right compartments, three scenes
    that placed it beside the slot and jammed it on a wall, certified)."""
    ax = book_axes(s, obj)
    if ax is None:
        return None
    corners = s.env.object_corners(obj)
    return ax.length, float(np.ptp(corners @ ax.thin))


def _off_upright(s: Scene, obj: str) -> float:
    """Radians between the book's up axis and vertical (0 when it is not book-shaped)."""
    ax = book_axes(s, obj)
    return 0.0 if ax is None else _tilt(ax.up)


def quarter_turn(ctx: Ctx, obj: str, ax: BookAxes, angle: float = 2 * PITCH, grasp_pitch: float = PITCH,
                 upright: bool = False) -> Plan:
    """Turn the book by `angle` (a quarter) in its own plane toward standing: hold it by a top
    corner with the hand pitched `grasp_pitch` one way along its plane, lift, pitch the hand
    the rest of `angle` the other way (`upright`: on, while the book lags short of upright),
    set it down where it was, let go."""
    s = ctx.scene
    grip, a1, a2 = _corner_grip(s, ax, angle, grasp_pitch)
    was = s.box(obj).centre[:2]  # a free spot: the book stood there
    yield from _edge_grasp_turn(ctx, obj, _held(ax, grip, a1), lift=_turn_lift(s, ax, grip), to=a2, rot_tol=0.06)
    yield Grip(1.0, SETTLE_STEPS // 2, label="settle")
    if upright:
        a2 = yield from _straighten(ctx, obj, np.cross(a1, a2), a2)
    yield from set_down(ctx, obj, was, a2, level=not upright)


def _corner_grip(s: Scene, ax: BookAxes, angle: float, grasp_pitch: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(grip site, grasp approach, approach after the turn) of `quarter_turn`: the top corner
    the hand pitched along `_turn_way`'s first approach comes to first, gripped CORNER_DEPTH_M in."""
    a1, a2 = _turn_way(s, ax, angle, grasp_pitch)
    corner = max(_plane_corners(ax), key=lambda p: float(-a1 @ p))
    return corner + a1 * CORNER_DEPTH_M, a1, a2


def edge_blockers(scene: Scene, obj: str, ax: BookAxes, keep: set[str]) -> list[str]:
    """The movable objects (not in `keep`) in the tilted hand's way where it closes on the
    book: at the top edge (`stand_up`) or at the corner of the turn `turn_first` asks for;
    boxes, padded by EDGE_ROOM_M, holding a point of the open fingers or of the palm behind
    them (`_hand_points`). The tilted hand comes down over whatever stands beyond the edge: a
    mug at a lying book's top edge took a finger and the palm, the edge move stalled 80 steps
    and the grasp missed; a book leaning on a mug was knocked flat by the hand on the mug,
    which was set aside only after that miss (measured: three tuning scenes, all timeouts)."""
    turn = turn_first(scene, ax)
    if turn is None:
        grip, approach = ax.top_mid - ax.up * SLAB_GRIP_BELOW_TOP, -ax.up
    else:
        grip, approach, _ = _corner_grip(scene, ax, *turn[:2])
    points = _hand_points(grip, approach, ax.thin)
    out = []
    for o in sorted(scene.env.object_names):
        if o == obj or o in keep:
            continue
        b = scene.box(o)
        if any(np.all(b.lo - EDGE_ROOM_M <= p) and np.all(p <= b.hi + EDGE_ROOM_M) for p in points):
            out.append(o)
    return out


def _hand_points(grip: np.ndarray, approach: np.ndarray, closing: np.ndarray) -> list[np.ndarray]:
    """Points of a hand open at `grip`, pointing along `approach`, closing along `closing`:
    the two fingertips, the fingers' roots and the palm's ends behind them."""
    tips = [grip + sg * closing * FINGER_REACH for sg in (-1.0, 1.0)]
    back = [grip - approach * d + sg * closing * r for d, r in PALM_POINTS_M for sg in (-1.0, 1.0)]
    return tips + back


def set_down(ctx: Ctx, obj: str, was: np.ndarray, a2: np.ndarray, level: bool) -> Plan:
    """Lower the book the hand holds, pointing along `a2`, until it stands just over the
    support at `was` (xy, where it lay or stood: free), let go, back off along the hand and
    rise; `level`: turning the hand back to pointing down on the way up."""
    s = ctx.scene
    box = s.box(obj)
    gap = box.lo[2] - s.support_top(was, 0.01, {obj})
    # turning about the grip site carried the book aside: back over where it was
    down = s.eef() + [*(was - box.centre[:2]), -max(gap - PUT_DOWN_GAP, 0.0)]
    yaw2 = ctx.yaw_hold
    ctx.approach_hold = a2
    try:
        yield ctx.move(down, gripper=1.0, speed=0.5, yaw=yaw2, approach=a2, tol=0.008, max_steps=35,
                       label="put_down")
        yield Grip(-1.0, ctx.open_steps, label="open")
        yield ctx.move(s.eef() - a2 * 0.04, yaw=yaw2, approach=a2, tol=0.015, max_steps=12, label="back_off")
    finally:
        ctx.approach_hold = None
    # `level` before another quarter (`quarter_turn` not `upright`: upside down, on a side):
    # the hand turns back to pointing down while it rises; left tilted, the next attempt first
    # sent it home across the table (`back_out`: an awkward arm) and back (measured: 55 steps
    # over an upside-down book's two turns). After a turn that stands the book it gained
    # nothing (the next grasp came at the same step) and a tuning book then jammed on the
    # compartment's rim: not there
    # a hand left pointing toward the base (a book stood up from its face or its top edge)
    # rises toward the base as it levels: straight up, the elbow stretched into its limit,
    # the hand stayed tilted, and undoing that (`unwind`, `back_out`) cost ~100 steps
    # (measured: `book_poses.py` upside down, seeds 11, 13 and 17, +13 certified, 3 lost)
    points_back = float(a2[:2] @ toward_base(s, 1.0)[:2]) > TOWARD_BASE
    pull = toward_base(s, RETREAT_PULL_M) if level and points_back else np.zeros(3)
    yield ctx.move(s.eef() + pull + [0.0, 0.0, 0.05], yaw=yaw2, tol=0.03, rot_tol=LEVEL_TOL if level else None,
                   max_steps=30 if level else 15, label="retreat")
    if abs(yaw2) > np.pi / 2 + 0.3:
        # the hand was turned half about its axis (out of range the other way): turn it back
        # up here, or the next grasp turns the wrist on its way down and knocks the book over
        # (measured)
        ctx.yaw_hold = _half_turned(yaw2)
        yield ctx.move(s.eef() + [0.0, 0.0, 0.04], yaw=ctx.yaw_hold, tol=0.03, rot_tol=0.1, max_steps=40,
                       label="unwind")


def _turn_way(s: Scene, ax: BookAxes, angle: float, grasp_pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """(grasp approach, approach after the turn) for `quarter_turn`: the hand pitched
    `grasp_pitch` toward one side along the book's plane, then the rest of `angle` toward
    the other. Of the two ways round, the one that gets the book nearer standing; where both
    do alike (upside down: either way), the one whose hand points away from the base:
    pointing back toward it, joint 7 ran into its limit, the hand never reached the corner
    and drifted off (measured: two tuning scenes, 240 steps lost each)."""
    m = np.cross(ax.thin, [0.0, 0.0, 1.0])  # the horizontal direction in the book's plane
    m /= max(float(np.linalg.norm(m)), 1e-6)
    down = np.array([0.0, 0.0, -1.0])
    away = ax.top_mid[:2] - s.env.robot_base()[:2]
    away /= max(float(np.linalg.norm(away)), 1e-6)
    options = []
    p1, p2 = grasp_pitch, angle - grasp_pitch
    for sg in (1.0, -1.0):  # pitch the hand toward +m, then toward -m; or the other way
        a1 = np.cos(p1) * down + np.sin(p1) * m * sg
        a2 = np.cos(p2) * down - np.sin(p2) * m * sg
        turn = axis_angle_matrix(np.cross(a1, a2), angle)
        gain = float((turn @ ax.up)[2] - ax.up[2])  # how much nearer standing it gets
        options.append((gain, float(a1[:2] @ away), a1, a2))
    top = max(o[0] for o in options)
    *_, a1, a2 = max((o for o in options if o[0] > top - GAIN_TIE), key=lambda o: o[1])
    return a1, a2


def _straighten(ctx: Ctx, obj: str, axis: np.ndarray, approach: np.ndarray) -> Plan:
    """Pitch the hand on about `axis` (the turn's) while the book it holds lags more than
    LAG_TOL short of upright, as far as MAX_TILT; returns the hand's approach then. Held by
    a corner, the book pivots in the fingers by a varying amount (measured: 17-29 deg on
    two tuning scenes), and set down short of upright it falls back to leaning."""
    s = ctx.scene
    n = axis / max(float(np.linalg.norm(axis)), 1e-9)
    for _ in range(STRAIGHTEN_TRIES):
        ax = book_axes(s, obj)
        if ax is None:
            break
        lag = float(np.arctan2(np.cross(ax.up, [0.0, 0.0, 1.0]) @ n, ax.up[2]))
        step = min(lag, MAX_TILT - float(np.arccos(np.clip(-approach[2], -1.0, 1.0))))
        if step < LAG_TOL:
            break
        approach = axis_angle_matrix(n, step) @ approach
        ctx.approach_hold = approach
        try:
            yield ctx.move(s.eef(), gripper=1.0, yaw=ctx.yaw_hold, approach=approach, tol=0.03, rot_tol=0.06,
                           max_steps=40, label="straighten")
            yield Grip(1.0, SETTLE_STEPS // 2, label="settle")
        finally:
            ctx.approach_hold = None
    return approach


def _half_turned(yaw: float) -> float:
    """The same hand turned by half a turn about its axis (fingers close along the same
    line), the yaw kept within a half turn of zero."""
    return yaw - np.pi if yaw > 0 else yaw + np.pi


def _rot_off(s: Scene, yaw: float, approach: np.ndarray | None) -> float:
    """Radians between the hand's orientation now and the one asked for."""
    return float(np.linalg.norm(rotation_error(hand_orientation(yaw, approach), s.env.eef_pose()[1])))


def _plane_corners(ax: BookAxes) -> list[np.ndarray]:
    """The book's four corners in its mid-plane (world)."""
    side = np.cross(ax.thin, ax.up)
    half = 0.5 * ax.length
    centre_top = ax.top_mid
    centre_bottom = (ax.ends[0] + ax.ends[1]) - centre_top  # ends' mean is the centre
    return [c + side * s * half for c in (centre_top, centre_bottom) for s in (-1.0, 1.0)]


def _edge_grasp_turn(ctx: Ctx, obj: str, ax: BookAxes, lift: float = LIFT_M, to: np.ndarray | None = None,
                     rot_tol: float = 0.03) -> Plan:
    """Grasp the edge at `ax.top_mid` with the hand pointing along -`ax.up`, lift, turn the
    hand down (`ax.up` then points up), or to point along `to`."""
    s = ctx.scene
    yaw, approach = tilted_grasp(ax)
    grip = ax.top_mid - ax.up * SLAB_GRIP_BELOW_TOP
    start = grip + ax.up * BACK_OFF_M
    # the hand turned by half a turn about its axis (same grasp) from the outset where the
    # wrist reaches that way round and not the other: tilted toward a joint-7 limit first, the
    # hand stalled TILT_STEPS before the turned yaw below (measured: ~60 steps, a timeout)
    off_rad = s.env.ik_residual(start, hand_orientation(yaw, approach))[1]
    if off_rad > REACH_TOL and s.env.ik_residual(start, hand_orientation(_half_turned(yaw), approach))[1] < off_rad:
        yaw = _half_turned(yaw)
    ctx.note(stand_book=True)
    if not s.gripper_open():
        yield Grip(-1.0, ctx.open_steps + 4, label="release")
    # the book itself counts: the hand must not sweep it over on the way (measured)
    lift_z = s.path_clearance(s.eef(), start, 0.06, set()) + HAND_CLEARANCE
    steep = _tilt(ax.up) > STEEP
    ctx.yaw_hold, ctx.approach_hold = yaw, approach  # Grip primitives hold this orientation
    try:
        # over the start point with the hand pointing down, then tilted there (turning it on
        # the way over took as long, and went wrong where the tilt is out of reach)
        yield from travel(ctx, start, yaw, -1.0, max(lift_z, start[2] + (TURN_ABOVE_M if steep else 0.0)))
        if steep:  # turn the hand up high first: turning it while going down
            # a long way, the controller lets the hand drift up and away (measured)
            yield ctx.move(start + [0.0, 0.0, TURN_ABOVE_M], yaw=yaw, approach=approach, tol=0.01, rot_tol=0.04,
                           max_steps=100, label="tilt")
        yield ctx.move(start, yaw=yaw, approach=approach, tol=0.006, rot_tol=rot_tol, max_steps=TILT_STEPS,
                       label="tilt")
        if _rot_off(s, yaw, approach) > REACH_TOL:
            # out of the wrist's range this way round (which way is, depends on where the book
            # lies: measured both ways): the hand turned by half a turn about its axis, same grasp
            yaw = _half_turned(yaw)
            ctx.yaw_hold = yaw
            yield ctx.move(start, yaw=yaw, approach=approach, tol=0.006, rot_tol=rot_tol, max_steps=TILT_STEPS,
                           label="tilt")
        yield ctx.move(grip, speed=0.3, yaw=yaw, approach=approach, tol=0.006, max_steps=80, label="edge")
        yield Grip(1.0, ctx.close_steps, label="close")
        up = s.eef() + [0.0, 0.0, lift]
        yield ctx.move(up, gripper=1.0, speed=0.6, yaw=yaw, approach=approach, tol=0.02, max_steps=50,
                       label="pick_lift")
    finally:
        ctx.approach_hold = None
    if to is not None:
        # the pitch about the closing axis undone and redone the other way: same yaw
        ctx.approach_hold = to
        yield ctx.move(s.eef(), gripper=1.0, yaw=yaw, approach=to, tol=0.03, rot_tol=0.06, max_steps=90,
                       label="turn")
        ctx.approach_hold = None
        return
    yield ctx.move(s.eef(), gripper=1.0, yaw=yaw, tol=0.03, rot_tol=0.06, max_steps=80, label="upright")
