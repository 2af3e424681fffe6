"""Skill: stand up a book lying on its face, by a pinch across one of its top corners.

Input: a `Ctx` and a book `obj` (`stand_book.book_axes`) whose faces lie within
`stand_book.FACE_UP` of level. No grasp of a parallel gripper takes such a book as it lies:
its face is 11 x 13.4 cm, wider than the open fingers either way, and its 2.9 cm thickness is
upright against the table (a pinch across the top end's edge was tried and left: README).
A corner is narrower: the fingers, the hand pointing down, close along a level line that cuts
off a top corner, CORNER_LEG_M along each of its two edge faces (a 4.2 cm chord); each pad
meets its face 45 deg from square, inside the pads' friction cone (friction 2.0: 63 deg).
Output: primitives that
1. pinch that corner low on its edge faces and lift: the pads hold the book rigid, level
   (measured: it does not pivot about the pinch line);
2. turn the hand with it by the book's whole tilt (a quarter) about the level axis that
   stands it up, rising TURN_RISE_M: the hand then points level along the book's old up
   axis, which the wrist reaches and holds high over the table (low over it, it does not:
   `stand_book.MAX_TILT`); where the arm behind the hand would then come down on something
   taller than the book, the hand also swivels about the vertical on the way, by the least
   that clears it and stays in the arm's reach (`arm_swivel`);
3. set it down on its bottom edge where it lay, let go (`stand_book.set_down`), and take
   the arm back to its home joints (`unwind`).
The next attempt finds a standing book and grasps it from above as usual. Of the two top
corners, the one the hand comes down to clearest of other objects goes first.
"""

from __future__ import annotations

from collections.abc import Generator

import numpy as np

from pipeline.policies.scripted.hand import FINGER_REACH, closing_yaw
from pipeline.policies.scripted.motion import HAND_CLEARANCE, Ctx, travel
from pipeline.policies.scripted.primitives import Grip, Primitive, axis_angle_matrix, hand_orientation
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.stand_book import FACE_UP, SETTLE_STEPS, BookAxes, book_axes, set_down
from pipeline.policies.scripted.recovery.unwind import unwind
from pipeline.policies.scripted.scene import TABLE_MARGIN, Scene
from pipeline.policies.scripted.stack import carried

CORNER_LEG_M = 0.03  # the pinch line meets each edge face this far from the corner
FINGER_ROOM_M = 0.012  # an open fingertip's spot on the table must be clear this far around
# corners are pinched in order of how much of the hand's line along its closing axis
# (HAND_HALF_M either way: the hand is wider than its open fingers) comes within CROWDED_M of
# another object standing HAND_ABOVE_M over the grip site: the hand came down on a mug or the
# caddy's wall and the fingers closed on nothing (measured: two tuning-state scenes)
CROWDED_M = 0.02
HAND_ABOVE_M = 0.04
HAND_HALF_M = 0.1
HOVER_M = 0.06
LIFT_SPEED = 0.5
TURN_MAX = np.radians(95.0)  # most the hand turns from pointing down, high over the table
LIFT_CLEAR_M = 0.03  # the turned book's lowest point over the table
# the turn's end this far over where the lift left the hand: at the lift's height the hand
# pointing level reached 88 deg from down, then sagged to 76 deg within 40 steps with
# joint 6 on its limit (the controller's null space pulls the arm toward home), the book
# leaned 14 deg short of standing and fell back on its face once let go; 8 cm higher it
# held 88-93 deg and the book stood (measured: two tuning scenes, STUDY_SCENE1)
TURN_RISE_M = 0.08
# set down standing, the hand points level along the book's old up axis and the arm behind
# it runs level at about the book's height: its wrist links came down on the caddy's wall
# 25 cm behind the grip, the book stalled 4.5 cm over the table, was let fall and lay on its
# face again (measured: a tuning scene, a timeout). Points ARM_BACK_M behind the grip there
# must be clear of the boxes (padded by ARM_ROOM_M, the links' radius) of things standing
# higher than the grip; else the lifted book is first swivelled about the vertical
# (SWIVELS, the least that clears them). Set down further along the hand instead, it went
# 15 cm out to the table's side, where the next grasp missed (measured: the same scene)
ARM_BACK_M = np.arange(0.08, 0.33, 0.03)
ARM_ROOM_M = 0.05
SWIVELS = np.radians([45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0])
SWIVEL_YAW_MAX = np.pi / 2 + 0.3  # the hand's yaw kept within this (`set_down` unwinds beyond)
REACH_M, REACH_RAD = 0.02, 0.05  # `ik_residual` within these: the turned hand is in reach


def lying_on_face(scene: Scene, obj: str) -> BookAxes | None:
    """The book's axes when `obj` is a book lying on a face; None otherwise."""
    ax = book_axes(scene, obj)
    return ax if ax is not None and abs(float(ax.thin[2])) > FACE_UP else None


def turned_approach(held: BookAxes) -> np.ndarray:
    """The hand's approach once it has turned with the lifted book by its whole tilt about
    the level axis that stands it (up high, the wrist reaches pointing level; low over the
    table it does not: `MAX_TILT`)."""
    tilt = float(np.arccos(np.clip(held.up[2], -1.0, 1.0)))
    axis = np.cross(held.up, [0.0, 0.0, 1.0])
    a2 = np.array([0.0, 0.0, -1.0])
    if np.linalg.norm(axis) > 1e-6:
        a2 = axis_angle_matrix(axis, min(tilt, TURN_MAX)) @ a2
    return a2


def arm_meets(scene: Scene, obj: str, spot: np.ndarray, height: float, a2: np.ndarray) -> list[str]:
    """The things standing higher than the grip whose boxes (padded by ARM_ROOM_M across)
    the arm behind a hand pointing along `a2` meets, the book (held at a top corner,
    `height` tall) set down standing at `spot`. A neighbour no taller than the book only
    grazes the links (measured: a standing book beside, certified)."""
    back = level(-a2)
    grip = np.array([spot[0], spot[1], scene.table_height() + height])
    points = [grip[:2] + back[:2] * d for d in ARM_BACK_M]
    hit = {name for name, b in scene.obstacle_boxes({obj, "table"}) if b[1, 2] > grip[2] + 0.01
           and any(np.all(b[0, :2] - ARM_ROOM_M <= p) and np.all(p <= b[1, :2] + ARM_ROOM_M) for p in points)}
    return sorted(hit)


def arm_swivel(scene: Scene, obj: str, held: BookAxes, spot: np.ndarray, yaw: float,
               turn_to: np.ndarray) -> tuple[float, np.ndarray]:
    """(radians, the hand's approach after the turn) of the swivel of the lifted book (and
    the hand's yaw) about the vertical before it is turned, so that the arm behind the hand
    clears what stands higher than the grip where the book is set down (`arm_meets`): none
    (0, `turned_approach`) when it does as it is, or when no swivel within the wrist's yaw
    (SWIVEL_YAW_MAX) does with the turned hand at `turn_to` in the arm's reach
    (`SimEnv.ik_residual` within REACH_M, REACH_RAD). A swivel that left the hand pointing
    level straight away from the base took joint 6 to its limit: the turn stalled, the hand
    drifted 20 cm up and the book was let go in the air (measured: a tuning scene, certified
    before)."""
    a2 = turned_approach(held)
    if not arm_meets(scene, obj, spot, held.height, a2):
        return 0.0, a2
    for swivel in SWIVELS:
        if abs(yaw + swivel) > SWIVEL_YAW_MAX:
            continue
        a = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), swivel) @ a2
        if arm_meets(scene, obj, spot, held.height, a):
            continue
        off_m, off_rad = scene.env.ik_residual(turn_to, hand_orientation(yaw + swivel, a))
        if off_m <= REACH_M and off_rad <= REACH_RAD:
            return float(swivel), a
    return 0.0, a2


def level(v: np.ndarray) -> np.ndarray:
    h = np.array([v[0], v[1], 0.0])
    return h / max(float(np.linalg.norm(h)), 1e-9)


def _corners(scene: Scene, ax: BookAxes) -> list[tuple[np.ndarray, np.ndarray]]:
    """(grip site, closing axis) of the pinch across each of the two top corners."""
    u = level(ax.up)
    side = level(ax.long)
    half = 0.5 * ax.length
    z = max(float(ax.top_mid[2]), scene.table_height() + TABLE_MARGIN)
    out = []
    for sg in (1.0, -1.0):
        corner = ax.top_mid + side * sg * half
        on_side, on_top = corner - u * CORNER_LEG_M, corner - side * sg * CORNER_LEG_M
        out.append((np.array([*((on_side + on_top) / 2)[:2], z]), level(on_side - on_top)))
    return out


def _tips(grip: np.ndarray, k: np.ndarray) -> list[np.ndarray]:
    return [grip + k * FINGER_REACH, grip - k * FINGER_REACH]


def _tip_free(scene: Scene, obj: str, tip: np.ndarray, exclude: frozenset[str] = frozenset()) -> bool:
    return scene.support_top(tip[:2], FINGER_ROOM_M, {obj, *exclude}) < scene.table_height() + 0.005


def corner_pinches(scene: Scene, obj: str, ax: BookAxes) -> list[tuple[np.ndarray, np.ndarray]]:
    """(grip site, closing axis) for each top corner whose two open fingertips land on free
    table, best first: the hand clearer of other objects (`_crowded`), then nearer the robot's base."""
    base = scene.env.robot_base()
    out = []
    for grip, k in _corners(scene, ax):
        if all(_tip_free(scene, obj, t) for t in _tips(grip, k)):
            crowded = _crowded(scene, obj, grip, k)
            out.append((crowded, float(np.linalg.norm((grip - base)[:2])), grip, k))
    return [(g, k) for *_, g, k in sorted(out, key=lambda o: (o[0], o[1]))]


def crowded_pinches(scene: Scene, obj: str, ax: BookAxes) -> bool:
    """Every top corner's hand line comes within CROWDED_M of something standing over the
    grip (`_crowded`): a pinch there came down on the caddy's wall, hovered against it for 85
    steps and closed on nothing, twice (measured: a tuning scene, a timeout)."""
    return all(_crowded(scene, obj, g, k) for g, k in _corners(scene, ax))


def pinch_clear_after(scene: Scene, obj: str, ax: BookAxes, shift: np.ndarray) -> bool:
    """Some top corner, the book slid by `shift`, has its fingertips' spots free and its hand
    line clear of the crowd (for `nudge.push_plan`, which slides it there first)."""
    for g, k in _corners(scene, ax):
        grip = g + [shift[0], shift[1], 0.0]
        if all(_tip_free(scene, obj, t) for t in _tips(grip, k)) and not _crowded(scene, obj, grip, k):
            return True
    return False


def pinch_blockers(scene: Scene, obj: str, ax: BookAxes, keep: set[str]) -> list[str]:
    """Where no top corner has room for the fingers (`corner_pinches`): the movable objects
    (not in `keep`) whose boxes take the fingertips' spots at the corner that they alone
    block (of two such corners, the one with fewer); [] where a corner is free or none is
    freed that way. Without a corner the attempt fell to top-down grasps of the flat book,
    which slid off it twice before the neighbour under the tip was set aside (measured: ~200
    steps, one tuning scene)."""
    loose = sorted(o for o in scene.env.object_names if o != obj and o not in keep)
    options = []
    for grip, k in _corners(scene, ax):
        blocked = [t for t in _tips(grip, k) if not _tip_free(scene, obj, t)]
        if not blocked:  # this corner can be pinched as it is
            return []
        movers = [o for o in loose if any(not _tip_free(scene, obj, t, frozenset(set(loose) - {o})) for t in blocked)]
        if all(_tip_free(scene, obj, t, frozenset(movers)) for t in blocked):
            options.append(movers)
    return min(options, key=len) if options else []


def _crowded(scene: Scene, obj: str, grip: np.ndarray, k: np.ndarray) -> int:
    """How many points of the hand's line come within CROWDED_M of another object reaching
    the hand (0: clear)."""
    line = [grip[:2] + k[:2] * d for d in np.linspace(-HAND_HALF_M, HAND_HALF_M, 11)]
    boxes = [b for name, b in scene.obstacle_boxes({obj}) if name != "table" and b[1, 2] > grip[2] + HAND_ABOVE_M]
    return sum(any(np.all(b[0, :2] - CROWDED_M <= p) and np.all(p <= b[1, :2] + CROWDED_M) for b in boxes)
               for p in line)


def stand_from_face(ctx: Ctx, obj: str, ax: BookAxes, attempt: int) -> Generator[Primitive, None, bool]:
    """Pinch a top corner (attempt k: the k-th best), lift, turn the book upright in the
    hand, set it down standing, let go. Returns False, having yielded nothing, when no corner
    has room for the fingers; True otherwise (the next attempt finds the book as it is)."""
    s = ctx.scene
    pinches = corner_pinches(s, obj, ax)
    if not pinches:
        return False
    grip, k = pinches[attempt % len(pinches)]
    yaw = min((closing_yaw(k), closing_yaw(-k)), key=abs)  # the same line: the wrist's middle
    was = s.box(obj).centre[:2]  # a free spot: the book lay there
    ctx.note(face_book=True)
    if not s.gripper_open():
        yield Grip(-1.0, ctx.open_steps + 4, label="release")
    hover = grip + [0.0, 0.0, HOVER_M]
    yield from travel(ctx, hover, yaw, -1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + HAND_CLEARANCE)
    yield ctx.move(hover, yaw=yaw, tol=0.012, rot_tol=0.1, label="hover")
    yield ctx.move(grip, speed=0.5, yaw=yaw, tol=0.006, max_steps=50, label="descend")
    ctx.yaw_hold = yaw
    yield Grip(1.0, ctx.close_steps, label="close")
    # the pinch holds the book level as it rises (measured: it does not pivot in the pads);
    # turned, its bottom edge swings down to its height below the fingers
    up = s.eef().copy()
    up[2] = s.table_height() + ax.height + LIFT_CLEAR_M
    yield ctx.move(up, gripper=1.0, speed=LIFT_SPEED, yaw=yaw, tol=0.02, max_steps=80, label="pick_lift")
    yield Grip(1.0, SETTLE_STEPS, label="settle")
    held = book_axes(s, obj)
    if held is None or not carried(s, obj, checks.held(s)):
        return True
    # swivelled on the way where the arm would meet something (`arm_swivel`): the book turns
    # with the hand about the vertical too
    turn_to = s.eef() + [0.0, 0.0, TURN_RISE_M]
    swivel, a2 = arm_swivel(s, obj, held, was, yaw, turn_to)
    yaw += swivel
    ctx.yaw_hold = yaw
    ctx.approach_hold = a2
    try:
        yield ctx.move(turn_to, gripper=1.0, yaw=yaw, approach=a2, tol=0.03,
                       rot_tol=0.06, max_steps=90, label="turn")
        yield Grip(1.0, SETTLE_STEPS // 2, label="settle")
    finally:
        ctx.approach_hold = None
    yield from set_down(ctx, obj, was, a2, level=True)
    # back to the home joints along a joint-space path: the hand came from pointing level far
    # out, and levelling it there (then backing out in the hand's space) left the elbow
    # locked straight, so the next grasp hovered 5 cm off the standing book until the
    # episode ran out (measured: one tuning scene, certified this way)
    yield from unwind(ctx)
    return True
