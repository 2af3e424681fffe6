"""Reading a live scene for what blocks the plan: hopeless objects, an awkward arm, a wrong
hold, objects in the way. Pure queries over `Scene`; nothing here moves the robot."""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.goal import PUT
from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.hand import FINGER_REACH, Grasp, closing_axis
from pipeline.policies.scripted.placement import sweep_clearance
from pipeline.policies.scripted.recovery.reasons import GiveUpReason
from pipeline.policies.scripted.scene import Scene, robot_base
from pipeline.sim.facts import JointKind

OFF_TABLE_M = 0.06  # a body this far below the table top has fallen off it
REACH_M = 0.95  # horizontal reach from the robot base the arm can still grasp at
# ... and the nearest: closer in, the folded arm hits itself or the base before the palm
# gets down (measured: a book fallen against the base, 0.28 m out, missed 3 of 3 grasps)
MIN_REACH_M = 0.25  # (to the object's nearest edge)
JOINT_MARGIN = 0.15  # radians from a joint limit that count as an awkward pose
# the elbow (joint 4) this close to its straight limit: the arm is near full reach, and
# raising the hand straight up stretches it into the limit, a singular pose from which the
# controller can no longer pull the hand back (measured: stuck 80 steps, 20 cm short of home)
ELBOW_STRAIGHT = 0.4
ELBOW_LOCKED = 0.06  # ... and this close it is locked: only tilting the hand bends it again
WRIST = slice(4, 7)  # the wrist joints (5, 6, 7)
PALM_HALF_M = 0.03  # the palm's half width across its closing axis (its box: 3.2 cm)
PALM_REACH_M = 0.10  # ... and its half length along it, from the grip site (its box: 20.8 cm)
# a drawer the palm's footprint meets by less than this is taken to let the hand down, its
# rounded end glancing off (measured: a pudding whose palm met the handle's box by 1.3 cm
# went down past it; one that met it by 4.2 cm, the front wall by 1.1 cm, stopped on the
# front). Not a clean line: another met the handle's box by 1.1 cm and stopped on it; the
# world-aligned footprint cannot tell the two apart
PALM_MEETS_M = 0.02
# an object's body this far beside a drawer's sweep is left where it is when a grasp's palm
# comes down clear of the opened drawer (a bowl 2.5 cm before KITCHEN_SCENE4's low bottom
# drawer was carried 33 cm off and back, ~120 steps; measured, a tuning scene)
SWEEP_BODY_PAD_M = 0.01
GRASP_TRIES = 6  # grasp candidates looked at
SAFE_Z = 0.16  # grip site above the table top from which any approach may start
# comfortable region of the grip site (x, y), relative to the robot base
HOME_XY = np.array([0.45, 0.0])
COMFORT_XY = np.array([[0.15, -0.45], [0.95, 0.45]])
LIFT_COST = 1.0  # metres of travel one metre of lift over obstacles is worth, choosing a free spot
# where free_spot looks, from the robot's base: (x, y) grids tried in order. First in front of
# the robot (far or close spots are slow); where that is full (KITCHEN_SCENE4: the bottom
# drawer's sweep and the counter's clutter left no spot, the bowl held aside -> `no_plan`),
# a wider ring the arm still reaches
SPOT_GRIDS = ((np.arange(0.42, 0.7, 0.03), np.arange(-0.3, 0.301, 0.03)),
              (np.arange(0.33, 0.76, 0.03), np.arange(-0.45, 0.451, 0.03)))


def moved_objects(scene: Scene) -> list[str]:
    """Objects the goal moves (first argument of `on` / `in`)."""
    return [c[1] for c in scene.env.goal if c[0] in PUT and c[1] in scene.env.object_names]


def hopeless(scene: Scene, objects: list[str]) -> tuple[GiveUpReason, str] | None:
    """A goal object fell off the table or lies beyond reach: the task cannot be finished."""
    table = scene.table_height()
    base = robot_base(scene)
    for o in objects:  # off the table first: a fallen object is usually also far away
        p = scene.env.object_pose(o)[0]
        if scene.box(o).hi[2] < table - OFF_TABLE_M:
            return GiveUpReason.OBJECT_OFF_TABLE, f"{o} at z {p[2]:.2f}, table top {table:.2f}"
    for o in objects:
        p = scene.env.object_pose(o)[0]
        r = float(np.linalg.norm(p[:2] - base[:2]))
        if r > REACH_M:
            return GiveUpReason.UNREACHABLE, f"{o} {r:.2f} m from the robot base"
        b = scene.box(o)
        near = float(np.linalg.norm(np.clip(base[:2], b.lo[:2], b.hi[:2]) - base[:2]))
        if near < MIN_REACH_M and scene.holding_any() == o and held(scene) is None:
            return GiveUpReason.UNREACHABLE, f"{o} lies against the robot, {near:.2f} m from its base"
    return None


def awkward_arm(scene: Scene) -> bool:
    """An arm joint near its limit, the grip site outside the comfortable region, or the
    hand tilted away from pointing down: approaches from here go wrong."""
    qs, limits = scene.env.arm_joints()
    for q, (lo, hi) in zip(qs, limits):
        if lo < hi and min(q - lo, hi - q) < JOINT_MARGIN:
            return True
    eef, rot = scene.env.eef_pose()
    rel = eef[:2] - robot_base(scene)[:2]
    if np.any(rel < COMFORT_XY[0]) or np.any(rel > COMFORT_XY[1]):
        return True
    return float(-rot[2, 2]) < np.cos(np.radians(25))  # grip axis more than 25 deg off vertical


def wrist_pinned(scene: Scene) -> bool:
    """A wrist joint within JOINT_MARGIN of its limit: the hand cannot turn or level past
    it, whatever the hand's position (a failing rollout flipped joint 5 by ~2.6 rad and left
    joint 6 at 3.75 of 3.75 rad: the hand stayed 10 deg tilted and every grasp missed)."""
    qs, limits = scene.env.arm_joints()
    return any(min(q - lo, hi - q) < JOINT_MARGIN for q, (lo, hi) in zip(qs[WRIST], limits[WRIST]))


def _elbow_slack(scene: Scene) -> float:
    """Radians the elbow (joint 4) can still straighten before its limit."""
    qs, limits = scene.env.arm_joints()
    return float(limits[3][1] - qs[3])


def held(scene: Scene) -> str | None:
    """The object between the fingers: `Scene.holding_any` also counts an object that only
    leans on the arm or the robot's base (a book fallen against it), which no opening of
    the gripper lets go; here a finger must touch it."""
    obj = scene.holding_any()
    if obj is None:
        return None
    left, right = scene.env.finger_contacts()
    return obj if obj in left | right else None


# closed fingers that touch nothing open on the way to a grasp at least this far off (the
# ramp to open takes ~8 steps, a travel this long ~20; a shorter one left them half shut over
# the object: tunewide's bowl stack, four missed grasps)
OPEN_ON_THE_WAY_M = 0.15


def opens_on_the_way(scene: Scene, obj: str | None) -> bool:
    """The gripper, closed on nothing and touching nothing, will be open before the hand
    gets to `obj` (its box centre at least OPEN_ON_THE_WAY_M off, horizontally): the next
    approach commands it open (a separate opening and back-off cost ~17 steps)."""
    left, right = scene.env.finger_contacts()  # (a held object is touched: `held`)
    if left or right or obj is None or obj not in scene.things():
        return False
    return float(np.linalg.norm(scene.box(obj).centre[:2] - scene.eef()[:2])) >= OPEN_ON_THE_WAY_M


def elbow_straight(scene: Scene) -> bool:
    return _elbow_slack(scene) < ELBOW_STRAIGHT


def elbow_locked(scene: Scene) -> bool:
    return _elbow_slack(scene) < ELBOW_LOCKED


def toward_base(scene: Scene, dist: float) -> np.ndarray:
    """Horizontal step of `dist` metres from the grip site toward the robot base."""
    d = robot_base(scene)[:2] - scene.eef()[:2]
    n = float(np.linalg.norm(d))
    return np.zeros(3) if n < 1e-6 else np.array([*(d / n * dist), 0.0])


def arm_in_contact(scene: Scene, held: str | None) -> bool:
    return any("robot" in pair and not (held and held in pair) for pair in scene.env.contacts())


def low_hand(scene: Scene) -> bool:
    return scene.eef()[2] < scene.table_height() + SAFE_Z


def _overlap(a: np.ndarray, b: np.ndarray, pad: float = 0.0) -> bool:
    return bool(np.all(a[0, :2] - pad <= b[1, :2]) and np.all(b[0, :2] - pad <= a[1, :2]))


def blockers(scene: Scene, obj: str, dest: np.ndarray, keep: set[str]) -> list[str]:
    """Movable objects in the way of moving `obj` to `dest` (x, y, support top): lying on
    top of `obj`, or standing on the support in the footprint it needs there. `keep` (goal
    objects, the target) are never moved aside."""
    box = scene.box(obj)
    half = box.size[:2] / 2
    foot = np.array([[*(dest[:2] - half * 0.8), 0.0], [*(dest[:2] + half * 0.8), 0.0]])
    on_top = np.array([box.lo, box.hi])
    loose = {o for o in scene.env.object_names if o != obj and o not in keep}
    # the support itself, without loose objects lying on it (`dest` may stand on them)
    support = scene.support_top(dest[:2], 0.6 * float(min(half)), loose | {obj}, below=dest[2] + 0.005)
    out = []
    for o in sorted(loose):
        b = scene.box(o)
        ob = np.array([b.lo, b.hi])
        if _overlap(ob, on_top) and b.lo[2] > box.hi[2] - 0.02:
            out.append(o)
        elif _overlap(ob, foot) and b.lo[2] > support - 0.04 and b.hi[2] > support + 0.005:
            out.append(o)
    return out


PALM_ENDS_M = (0.05, 0.1)  # points of the palm along the closing axis, either way from the grip site


def palm_points(grasp, reaches: tuple[float, ...] = PALM_ENDS_M, half_width: float = PALM_HALF_M) -> list[np.ndarray]:
    """Where the palm comes down with `grasp`: `reaches` either way along the closing axis,
    `half_width` either side across it (0: its middle line only)."""
    ax = closing_axis(grasp.yaw)
    side = np.array([-ax[1], ax[0], 0.0])
    return [grasp.pos + sg * ax * r + t * side * half_width
            for sg in (-1, 1) for r in reaches for t in ((-1, 1) if half_width > 0 else (0,))]


def covers(lo: np.ndarray, hi: np.ndarray, points: list[np.ndarray], pad: float = 0.005) -> bool:
    """A box (lo, hi) covers one of `points` seen from above, padded by `pad`."""
    return any(np.all(lo[:2] - pad <= p[:2]) and np.all(p[:2] <= hi[:2] + pad) for p in points)


def grasp_blockers(scene: Scene, obj: str, grasp, keep: set[str], half_width: float = PALM_HALF_M) -> list[str]:
    """Movable objects standing where the palm's ends go down when grasping `obj` with
    `grasp` (the palm reaches ~10 cm either way along the closing axis, ~5 cm above the
    grip site; `half_width` across it, 0: its middle line only): the best grasp of a flat
    box next to a tall carton is such a case."""
    points = palm_points(grasp, half_width=half_width)
    out = []
    for o in scene.env.object_names:
        if o == obj or o in keep:
            continue
        b = scene.box(o)
        if b.hi[2] < grasp.pos[2] + 0.05:
            continue
        if covers(b.lo, b.hi, points):
            out.append(o)
    return out


def tip_blockers(scene: Scene, obj: str, grasp, keep: set[str]) -> list[str]:
    """Movable objects in an open finger's way when grasping `obj` with `grasp`: under a
    fingertip (~4.7 cm either way along the closing axis) or between it and the object,
    higher than the tips (~1 cm below the grip site). The hand closes on them too
    (measured: a lying bottle grasped beside a bowl came up with the bowl clamped to it; a
    bowl's rim grasp beside the bottle's neck took the bottle along)."""
    ax = closing_axis(grasp.yaw)
    tip_z = grasp.pos[2] - 0.012
    top = max(tip_z, scene.box(obj).hi[2]) + 0.4
    side = np.array([-ax[1], ax[0], 0.0])
    hits = []
    for sg in (-1, 1):
        for r in (FINGER_REACH, 0.036, 0.026):
            for t in (-0.01, 0.0, 0.01):  # a finger is ~2 cm wide
                p = grasp.pos + sg * ax * r + t * side
                if scene.env.ray_down(p[:2], top, tip_z + 0.005, ignore=obj) is not None:
                    hits.append(p)
    out = []
    for o in scene.env.object_names:
        if o == obj or o in keep:
            continue
        b = scene.box(o)
        if b.hi[2] > tip_z + 0.005 and any(np.all(b.lo[:2] - 0.004 <= p[:2]) and np.all(p[:2] <= b.hi[:2] + 0.004)
                                           for p in hits):
            out.append(o)
    return out


def clear_grasp_choice(scene: Scene, obj: str, dest: np.ndarray | None, start: int, tries: int = 6) -> int:
    """The first grasp candidate from `start` on whose fingers touch no other object (see
    `tip_blockers`), or `start` when every one does."""
    for k in range(start, start + tries):
        if not tip_blockers(scene, obj, plan_grasp(scene, obj, dest, k), set()):
            return k
    return start


def drawer_sweep(scene: Scene, joint: str) -> np.ndarray | None:
    """(2, 3) box the drawer of a slide `joint` covers from now until fully open, or None
    for a hinge."""
    if scene.env.joint_frame(joint).kind != JointKind.SLIDE:
        return None
    now = _drawer_box(scene, joint)
    opened = now + _to_open(scene, joint)
    return np.array([np.minimum(now[0], opened[0]), np.maximum(now[1], opened[1])])


def drawer_opened(scene: Scene, joint: str) -> np.ndarray:
    """(2, 3) box of the drawer of a slide `joint` pulled fully out."""
    return _drawer_box(scene, joint) + _to_open(scene, joint)


def _drawer_box(scene: Scene, joint: str) -> np.ndarray:
    """(2, 3) box of the drawer of slide `joint` where it is now."""
    boxes = scene.env.joint_part_boxes(joint)
    return np.array([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])


def _to_open(scene: Scene, joint: str) -> np.ndarray:
    """(3,) shift of slide `joint`'s drawer from where it is to fully out."""
    fr = scene.env.joint_frame(joint)
    open_q = fr.range[0] if abs(fr.range[0]) > abs(fr.range[1]) else fr.range[1]
    return fr.axis * (open_q - fr.qpos)


OPEN_MIN_M = 0.02  # a drawer out less than this overhangs nothing in front of the cabinet


def palm_footprint(g: Grasp) -> np.ndarray:
    """The open hand's palm over grip `g`, as a world-aligned box (rows lo, hi; x, y used)."""
    ax = closing_axis(g.yaw)
    half = np.abs(ax) * PALM_REACH_M + np.abs(ax[[1, 0, 2]]) * PALM_HALF_M
    return np.array([g.pos - half, g.pos + half])


def candidate_palms(scene: Scene, obj: str, tries: int = GRASP_TRIES) -> list[np.ndarray]:
    """`palm_footprint` of each of `obj`'s first `tries` grasp candidates."""
    return [palm_footprint(plan_grasp(scene, obj, None, k)) for k in range(tries)]


def overhanging_drawer(scene: Scene, obj: str, pad: float = 0.02, tries: int = GRASP_TRIES) -> str | None:
    """The region of an open drawer that overhangs `obj` (a bowl left under the top drawer
    it was to go into), or the way down to it (the palm of each of its first `tries` grasp
    candidates), when closing the drawer would uncover it; else None. The palm comes down
    around the object, so `pad` widens its footprint; it reaches 10 cm along its closing
    axis, so a drawer's front a few cm out from the object stops it on the way down
    (measured: a pudding 7 cm in front of KITCHEN_SCENE10's open top drawer, the hand on
    the drawer's front 17 cm over the grip site, four times; by less than PALM_MEETS_M it
    glances off). No grasp reaches under a drawer whose floor is a hand's height over the
    object: the forearm comes down onto the drawer (see `under_drawer`)."""
    b = scene.box(obj)
    ob = np.array([b.lo, b.hi])
    palms = None
    for name in scene.env.region_names:
        joints = scene.env.region(name).joints
        if not joints or scene.env.joint_frame(joints[0]).kind != JointKind.SLIDE:
            continue
        fr = scene.env.joint_frame(joints[0])
        # closed is q = 0 (LIBERO's drawers slide over [-0.16, 0.01]: the range's end nearest
        # 0 is pushed 1 cm in, and taking it for closed made every shut drawer "open")
        closed_q = float(np.clip(0.0, *sorted(fr.range)))
        if abs(fr.qpos - closed_q) < OPEN_MIN_M:
            continue
        boxes = scene.env.joint_part_boxes(joints[0])
        now = np.array([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])
        shut = now + fr.axis * (closed_q - fr.qpos)
        if now[0, 2] <= b.hi[2]:
            continue
        if _overlap(now, ob, pad) and not _overlap(shut, ob, pad):
            return name
        if palms is None:
            palms = candidate_palms(scene, obj, tries)
        if all(_overlap(now, p, -PALM_MEETS_M) and not _overlap(shut, p) for p in palms):
            return name
    return None


def proud_in_drawer(scene: Scene, joint: str, margin: float = 0.01) -> list[str]:
    """Objects standing in the drawer of a slide `joint` whose top rises above its walls (a
    bowl leaning on the front wall): closing the drawer jams them against the cabinet."""
    if scene.env.joint_frame(joint).kind != JointKind.SLIDE:
        return []
    boxes = scene.env.joint_part_boxes(joint)
    lo, hi = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
    out = []
    for o in scene.env.object_names:
        b = scene.box(o)
        inside = np.all(b.centre[:2] > lo[:2]) and np.all(b.centre[:2] < hi[:2]) and lo[2] - 0.02 < b.lo[2] < hi[2]
        if inside and b.hi[2] > hi[2] + margin:
            out.append(o)
    return out


PERCHED_M = 0.03  # an object's bottom this far over the drawer's lowest part rests on a wall


def perched_in_drawer(scene: Scene, joint: str, obj: str) -> bool:
    """`obj` rests on a wall of the drawer of slide `joint`, not on its floor (measured: a
    bowl half on the side wall, its bottom 6.6 cm up; the floor is 1.1 cm thick)."""
    return bool(scene.box(obj).lo[2] > scene.env.joint_part_boxes(joint)[:, 0, 2].min() + PERCHED_M)


FLOOR_CLEAR_M = 0.02  # a drawer's floor this far over an object's top passes over it
HAND_HEIGHT_M = 0.15  # grip site to the top of the hand coming down on a grasp


def sweep_spares(scene: Scene, obj: str, joint: str, grasp) -> bool:
    """Opening the drawer of slide `joint` leaves `obj` alone and graspable by `grasp`: the
    object stands beside the sweep and some grasp's palm comes down clear of the opened
    drawer (SWEEP_BODY_PAD_M); or the drawer's floor passes over the object's top clear, and
    the opened drawer is either a hand's height over the grasp or clear of where the palm and
    the object are (see `grasp_blockers` for the palm). `under_sweep` pads the object by a
    hand's reach; a bowl beside a cabinet whose open drawer ended 3 cm before it, 10 cm over
    its rim, was set aside (~160 steps)."""
    sweep = drawer_sweep(scene, joint)
    b = scene.box(obj)
    if sweep is None:
        return False
    opened = drawer_opened(scene, joint)
    if not _overlap(np.array([b.lo, b.hi]), sweep, pad=SWEEP_BODY_PAD_M) and any(
            not _overlap(p, opened) for p in candidate_palms(scene, obj)):
        return True
    if sweep[0, 2] < b.hi[2] + FLOOR_CLEAR_M:
        return False
    if opened[0, 2] > grasp.pos[2] + HAND_HEIGHT_M:
        return True
    in_palm = covers(opened[0], opened[1], palm_points(grasp, (0.0, *PALM_ENDS_M)))
    return not in_palm and not _overlap(np.array([b.lo, b.hi]), opened, pad=0.02)


def under_sweep(scene: Scene, obj: str, sweep: np.ndarray, margin: float = 0.05) -> bool:
    """The opened drawer would overhang `obj` (or the hand grasping it, `margin`)."""
    b = scene.box(obj)
    return _overlap(np.array([b.lo, b.hi]), sweep, pad=margin) and b.hi[2] < sweep[1, 2]


def free_spot(scene: Scene, obj: str, avoid: list[np.ndarray], forbid: list[np.ndarray] = (),
              corridor_m: float = 0.0) -> np.ndarray | None:
    """A table spot (xy) where `obj` can stand without touching anything, near the hand,
    away from the points in `avoid` (goal targets), inside the comfortable region, and
    preferably reached without lifting the hand (a corridor of `corridor_m` either side)
    over tall things: every metre of lift costs LIFT_COST metres of travel (a carry over a
    drawer front or a cabinet rises and comes down again, ~50 steps)."""
    box = scene.box(obj)
    r = float(np.linalg.norm(box.size[:2])) / 2 + 0.03
    table = scene.table_height()
    base = robot_base(scene)[:2]
    eef = scene.eef()[:2]
    boxes = [b for _, b in scene.obstacle_boxes({obj}) if b[1, 2] > table + 0.005]
    home = base + HOME_XY

    def free(xy: np.ndarray) -> bool:
        sq = np.array([[*(xy - r), 0.0], [*(xy + r), 0.0]])
        return not any(_overlap(b, sq) for b in boxes) and not any(_overlap(f, sq, pad=0.05) for f in forbid)

    def cost(xy: np.ndarray) -> float:
        c = float(np.linalg.norm(xy - eef)) + float(np.linalg.norm(xy - home))
        if corridor_m > 0:
            c += LIFT_COST * (sweep_clearance(scene, box.centre, xy, corridor_m, {obj}) - table)
        return c + sum(max(0.0, 0.2 - float(np.linalg.norm(xy - a[:2]))) * 5 for a in avoid)

    for xs, ys in SPOT_GRIDS:
        spots = [xy for xy in (base + [x, y] for x in xs for y in ys) if free(xy)]
        if spots:
            return min(spots, key=cost)  # the first of equal costs, as the grid runs
    return None
