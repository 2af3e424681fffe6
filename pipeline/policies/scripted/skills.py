"""Skills: goal conjuncts turned into primitive sequences, reading live state as they go.

Each skill is a generator that yields `Move`/`Grip` primitives. The policy resumes it
only after the previous primitive finished and only at an action-chunk boundary, so
every decision (where the object is now, whether it is held, how far a drawer is open)
uses the live simulator state. A skill returns when its conjunct holds or it gives up.

Inputs: a `Ctx` (scene, noise). Invariants: positions are grip-site targets in world
coordinates; the hand points down; skills never read the goal flag to act, only to stop
early or retry (a real expert looks at what it did).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.noise import Noise
from pipeline.policies.scripted.primitives import Grip, Move, Primitive
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.stack import carried  # a stack of bowls counts as held
from pipeline.policies.scripted.truth import TruthLog

Plan = Iterator[Primitive]
HAND_CLEARANCE = 0.07  # grip site above obstacles when the hand moves empty
CARRY_CLEARANCE = 0.04  # held object's bottom above obstacles in transit
MAX_Z = 1.35  # keep targets inside the arm's comfortable workspace
REGION_INSIDE = 0.8  # fraction of a region's half extent a placed body is kept within
STAND_MIN_TILT, STAND_MAX_TILT = 4.0, 45.0  # degrees: a held object tilted this much is stood up
STAND_GAP = 0.004  # ... lowered until its upright bottom is this far above the support
STAND_TOL = 0.016  # ... or the hand is this close to there


@dataclass
class Ctx:
    scene: Scene
    noise: Noise
    max_attempts: int = 3
    close_steps: int = 14
    open_steps: int = 8
    yaw_hold: float = 0.0  # hand yaw while carrying (the yaw it grasped with)
    approach_hold: np.ndarray | None = None  # set while the hand is tilted (drawer handles)
    events: list[str] = field(default_factory=list)  # what went wrong, in order (for reports)
    truth: TruthLog | None = None  # the generator's own record (None: not recorded)

    def note(self, **noise) -> None:
        if self.truth is not None:
            self.truth.note(**noise)

    def begin(self, skill: str, conjunct: tuple[str, ...], target: str, reference: str | None = None) -> None:
        if self.truth is not None:
            self.truth.begin(skill, conjunct, target, reference)

    def end(self, outcome: str, detail: str = "") -> None:
        if self.truth is not None:
            self.truth.end(outcome, detail)

    def move(self, target, speed: float = 1.0, **kw) -> Move:
        t = np.asarray(target, dtype=float).copy()
        t[2] = min(t[2], MAX_Z)
        return Move(target=t, speed=min(1.0, speed * self.noise.speed), **kw)


def travel(ctx: Ctx, dest: np.ndarray, yaw: float, gripper: float, lift_z: float) -> Plan:
    """Rise to `lift_z` (if lower), cross over to above `dest` at that height."""
    eef = ctx.scene.eef()
    z = max(lift_z, dest[2])
    if eef[2] < z - 0.015:
        yield ctx.move([eef[0], eef[1], z], gripper=gripper, yaw=yaw, tol=0.02, label="lift")
    yield ctx.move([dest[0], dest[1], z], gripper=gripper, yaw=yaw, tol=0.015, label="transport")


def free_hand(ctx: Ctx) -> Plan:
    """Open the gripper if it is not open (it holds nothing useful), and back off upwards."""
    s = ctx.scene
    if not s.gripper_open():
        yield Grip(-1.0, ctx.open_steps + 4, label="release")
        eef = s.eef()
        yield ctx.move(eef + [0, 0, 0.06], tol=0.02, label="back_off")


def grasp(ctx: Ctx, obj: str, dest: np.ndarray | None = None, choice: int = 0, hover_m: float = 0.08,
          turn_tol: float | None = None, g=None) -> Plan:
    """Reach above the object, descend, close, lift. `choice` / `hover_m`: another grasp
    candidate and a higher hover (the recovery expert's retries). `turn_tol` (radians): the
    hover also waits until the hand has turned to the grasp's yaw, so a hand still turning
    does not sweep its fingers into the object on the way down (the recovery expert; a
    plain expert's start leaves little to turn). `g`: a `Grasp` chosen by the caller
    instead (the recovery expert's, see recovery/long_grasp.py)."""
    s = ctx.scene
    g = g if g is not None else plan_grasp(s, obj, dest, choice)
    offset = ctx.noise.grasp_offset()
    ctx.note(grasp_offset=offset)
    pos = g.pos + offset
    lift_z = s.path_clearance(s.eef(), pos, 0.06, {obj}) + HAND_CLEARANCE
    hover = pos + [0, 0, hover_m]
    yield from travel(ctx, hover, g.yaw, -1.0, lift_z)
    yield ctx.move(hover, yaw=g.yaw, tol=0.012, label="hover", rot_tol=turn_tol)
    t = ctx.noise.timing()
    ctx.note(grasp_timing=t)
    early = {"switch_gripper": 1.0, "switch_dist": 0.005 * -t} if t < 0 else {}
    yield ctx.move(pos, speed=0.5, yaw=g.yaw, tol=0.007, max_steps=50, label="descend", **early)
    ctx.yaw_hold = g.yaw
    yield Grip(1.0, ctx.close_steps + max(t, 0), label="close")
    yield ctx.move(s.eef() + [0, 0, 0.1], gripper=1.0, speed=0.6, yaw=g.yaw, tol=0.02, label="pick_lift")


def region_box(env, region: str) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half extents (world axes) of a region site."""
    r = env.region(region)
    return r["pos"], np.abs(r["mat"]) @ r["size"]


def place_xy(ctx: Ctx, obj: str, target: str) -> np.ndarray:
    return _place_choice(ctx, obj, target)[0]


def place_room(ctx: Ctx, obj: str, target: str) -> bool:
    """Whether `target` has a spot where `obj` goes in clear of walls and overhangs."""
    return _place_choice(ctx, obj, target)[1] == 0


# a long object lying in a drawer (a toppled wine bottle, 18 cm) may fit only turned along the
# drawer: hand turns tried, least first, when no spot is clear at the object's own yaw
TURNS = (-np.pi / 4, np.pi / 4, -np.pi / 2, np.pi / 2)
LONG_RATIO = 1.8  # footprint length / width above which turns are tried
HAND_SPAN = 0.09  # the closed fingers' outer width across a held object: clear of walls and handles too
# the hand's housing above the fingers: ~20 cm along the closing axis, ~6 cm across, from
# ~7 cm over the drawer floor: off the drawer it meets the cabinet's face (it clears a low
# front wall, and the handles hanging over the drawer from above)
HOUSING_HALF, HOUSING_Z = np.array([0.03, 0.10]), 0.07


def _carried_foot(s: Scene, obj: str, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """Size (xy) and centre relative to the body origin of the footprint the object comes
    down with: its box as it is, or turned by `turn` (`_turned_foot`)."""
    if turn == 0:
        return s.box(obj).size[:2], box_centre_offset(s, obj)
    return _turned_foot(s, obj, turn)


def _turned_foot(s: Scene, obj: str, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """Size (xy) and centre relative to the body origin of the object's footprint box after
    the hand turns it by `turn` about the vertical."""
    c, sn = np.cos(turn), np.sin(turn)
    rel = (s.env.object_corners(obj)[:, :2] - s.env.object_pose(obj)[0][:2]) @ np.array([[c, sn], [-sn, c]])
    lo, hi = rel.min(axis=0), rel.max(axis=0)
    return hi - lo, (lo + hi) / 2


def footprint_widths(s: Scene, obj: str) -> list[float]:
    """The object's footprint width across 36 directions of the plane (5 degrees apart)."""
    xy = s.env.object_corners(obj)[:, :2]
    return [float(np.ptp(xy @ [np.cos(t), np.sin(t)])) for t in np.linspace(0, np.pi, 36, endpoint=False)]


def _is_long(s: Scene, obj: str) -> bool:
    widths = footprint_widths(s, obj)
    return max(widths) > LONG_RATIO * min(widths)


def _place_choice(ctx: Ctx, obj: str, target: str) -> tuple[np.ndarray, int, float]:
    """Where the object's body should end up (xy), how many footprint cells are blocked there,
    and the hand turn (rad) to carry it with: on an object's body or a region's centre; in a
    drawer, the point nearest its centre where the object's footprint lies inside the walls
    with open sky above (an open bottom drawer lies partly under the drawers above it and
    their handles); a long object that fits nowhere as it lies is tried turned (`TURNS`)."""
    s = ctx.scene
    xy = s.pos(target)[:2].copy()
    if not s.env.is_region(target):
        return xy, 0, 0.0
    r = s.env.region(target)
    drawer = bool(r["joints"])
    _, half = region_box(s.env, target)
    top = r["pos"][2] + half[2]
    size = s.box(obj).size[:2]
    # other objects already standing in the region (the second moka pot on a stove)
    reach = 0.5 * float(max(size))  # objects within this of the region count
    others = [s.box(o) for o in s.env.object_names if o != obj]
    others = [b for b in others if np.all(b.hi[:2] > xy - half[:2] - reach) and np.all(b.lo[:2] < xy + half[:2] + reach)]
    if s.env.region(target)["parent"] in s.env.object_names:
        others = []  # a container object (a basket): things may share its middle
    if not drawer and not others:
        return xy, 0, 0.0
    key, spot = _best_spot(s, obj, r, half, top, xy, others, size, None)
    best = (key, spot, 0.0)
    if drawer and key[0] > 0 and _is_long(s, obj):
        # judged again with the hand and the footprint's true extent, as it lies and turned
        best = None
        for turn in (0.0, *TURNS):
            size_t, shift_t = _turned_foot(s, obj, turn)
            # the fingers close across its width at its middle and go down with it
            size_t[np.argmin(size_t)] = max(float(size_t.min()), HAND_SPAN)
            key, spot = _best_spot(s, obj, r, half, top, xy, others, size_t, shift_t)
            if best is None or key[0] < best[0][0]:
                best = (key, spot, turn)
            if best[0][0] == 0:
                break
    return best[1], best[0][0], best[2]


def _best_spot(s: Scene, obj: str, r: dict, half: np.ndarray, top: float, xy: np.ndarray, others: list,
               size: np.ndarray, shift: np.ndarray | None) -> tuple[tuple, np.ndarray]:
    """((blocked cells, crowd and distance), body xy) of the best grid point; `shift` (a
    turned footprint's centre from the body) also makes footprint cells off the region count."""
    drawer = bool(r["joints"])
    best = None
    # a drawer leaves a window only a few mm long between its front wall and the handles
    # of the drawers above (the white cabinet's bottom drawer and a bowl): a fine grid
    # along its axis, and the object's footprint (not its body origin) kept off both
    fine = int(np.argmax(np.abs(np.asarray(s.env.joint_frame(r["joints"][0])["axis"][:2])))) if drawer else -1
    nx, ny = (41 if fine == 0 else 7 if drawer else 11), (41 if fine == 1 else 7 if drawer else 11)
    blocked = (_drawer_clearance(s, obj, r["joints"][0], r["pos"][:2], half[:2], top, size, shift) if drawer
               else (lambda p: 0))
    # on a region (not in a drawer) the body must end inside it (LIBERO's `On` tests the body
    # origin against the region's extent): a spot on its very edge, where a crowded region
    # (the second moka pot beside the first) pushed it, left the body just outside
    edge = 1.0 if drawer else REGION_INSIDE
    for fx in np.linspace(-edge, edge, nx):
        for fy in np.linspace(-edge, edge, ny):
            p = r["pos"][:2] + half[:2] * [fx, fy]
            # overlap (m^2) of the footprint with objects already there: least wins
            c = p if shift is None else p + shift  # the object's own box is taken centred on its body
            lo, hi = c - size / 2, c + size / 2
            crowd = sum(float(np.prod(np.clip(np.minimum(hi, b.hi[:2]) - np.maximum(lo, b.lo[:2]), 0, None)))
                        for b in others)
            # footprint cells over a wall or under an overhang: fewest wins (none, where there is room)
            d = (blocked(p), 100 * crowd + float(np.linalg.norm(p - xy)))
            if best is None or d < best[0]:
                best = (d, p)
    return best if best is not None else ((0, 0.0), xy)


def _drawer_clearance(s: Scene, obj: str, joint: str, centre: np.ndarray, half: np.ndarray, top: float,
                      size: np.ndarray | None = None, shift: np.ndarray | None = None):
    """For a drawer region: a function of the object's body xy giving how many cells of its
    footprint (a rounded box, 4 mm margin) lie over a wall or under an overhang (anything
    struck by a ray from above higher than 2 cm over the drawer floor). Heights are ray-cast
    once on a 5 mm grid. `size`/`shift`: a turned footprint (default: the object's box); with
    them the grid also covers the shifted footprint, its cells 1 cm off the region count, and
    so do the cells under the hand's housing (`HOUSING_HALF`) off the region where something
    stands higher than `HOUSING_Z` over the floor."""
    floor = s.support_top(centre, 0.01, {obj}, below=top)
    box = s.box(obj)
    edge = 0.5 * (box.size[:2] if size is None else size) + 0.004
    turned = shift is not None
    if not turned:
        shift = box.centre[:2] - s.env.object_pose(obj)[0][:2]
    margin = edge + (np.abs(shift) if turned else 0.0)
    step = 0.005
    xs = np.arange(centre[0] - half[0] - margin[0], centre[0] + half[0] + margin[0] + step, step)
    ys = np.arange(centre[1] - half[1] - margin[1], centre[1] + half[1] + margin[1] + step, step)
    heights = np.array([[np.nan if (h := s.env.ray_down(np.array([x, y]), top + 0.5, floor, ignore=obj)) is None
                         else h for y in ys] for x in xs])
    hit = heights > floor + 0.02  # (nan: nothing above the floor there)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    # the drawer's own walls are thinner than the grid step: mark them from their boxes
    for b in s.env.joint_part_boxes(joint):
        if b[1, 2] > floor + 0.02:
            hit |= (gx >= b[0, 0] - step / 2) & (gx <= b[1, 0] + step / 2) & (gy >= b[0, 1] - step / 2) & (gy <= b[1, 1] + step / 2)
    high = None
    if turned:
        # the housing over a long object held across its middle (its short side: the closing axis)
        housing = HOUSING_HALF if size[0] > size[1] else HOUSING_HALF[::-1]
        high = (heights > floor + HOUSING_Z) & ((np.abs(gx - centre[0]) > half[0]) | (np.abs(gy - centre[1]) > half[1]))
        # off the drawer: over the table or the cabinet, not in it
        hit |= (np.abs(gx - centre[0]) > half[0] + 0.01) | (np.abs(gy - centre[1]) > half[1] + 0.01)

    def blocked(p: np.ndarray) -> int:
        c = p + shift
        inside = ((gx - c[0]) / edge[0]) ** 4 + ((gy - c[1]) / edge[1]) ** 4 <= 1.0
        n = int(np.count_nonzero(hit & inside))
        if high is not None:
            n += int(np.count_nonzero(high & (np.abs(gx - c[0]) <= housing[0]) & (np.abs(gy - c[1]) <= housing[1])))
        return n

    return blocked


def box_centre_offset(s: Scene, obj: str) -> np.ndarray:
    """xy of the object's box centre relative to its body origin (a bowl's is off-centre)."""
    return s.box(obj).centre[:2] - s.env.object_pose(obj)[0][:2]


def support_ceiling(env, target: str) -> float:
    """Boxes whose top is at or above this height cannot support an object put `in`/`on`
    `target`: for a region, a little above its top; for a region inside a drawer, its top
    itself (the cabinet's own top sits just above the top drawer's region)."""
    if not env.is_region(target):
        return np.inf
    r = env.region(target)
    top = r["pos"][2] + float(np.abs(r["mat"] @ r["size"])[2])
    return top if r["joints"] else top + 0.03


def destination(ctx: Ctx, obj: str, target: str) -> np.ndarray:
    """(x, y, support top) where the object's body should come to rest (no noise)."""
    s = ctx.scene
    dest, _, turn = _place_choice(ctx, obj, target)
    size, shift = _carried_foot(s, obj, turn)
    foot = dest + shift
    below = support_ceiling(s.env, target)
    radius = 0.6 * float(min(size[0], size[1])) / 2
    return np.array([dest[0], dest[1], s.support_top(foot, radius, {obj}, below=below)])


def place(ctx: Ctx, obj: str, target: str, stand: bool = False, shift: np.ndarray | None = None) -> Plan:
    """`stand`: see `place_at` (the recovery expert). `shift`: xy subtracted from the spot of a
    plain placement (the recovery expert centres a lying long object's length on the region;
    the own-way placements above, shelves, slots, a pan slid in, are not shifted)."""
    # a book into a narrow compartment or a roofed shelf goes in its own way (slot.py,
    # shelf.py, tip_push.py; imported here because they build on this module's `travel`)
    from pipeline.policies.scripted.shelf import open_side, shelf_opening, slide_into_shelf
    from pipeline.policies.scripted.slot import place_in_slot, slot_alignment
    from pipeline.policies.scripted.tip_push import tip_and_push

    into = shelf_opening(ctx, obj, target)
    if into is not None:
        yield from slide_into_shelf(ctx, obj, target, into)
        return
    into = open_side(ctx, obj, target)
    if into is not None:  # a gap too low for the tilted hand: tip the book flat, push it in
        yield from tip_and_push(ctx, obj, target, into)
        return
    angle = slot_alignment(ctx, obj, target)
    if angle is not None:
        yield from place_in_slot(ctx, obj, target, angle)
        return
    from pipeline.policies.scripted import slide_in  # builds on this module's `travel`

    comp = slide_in.compartment(ctx.scene, target)
    if comp is not None and slide_in.hand_stays_out(ctx, obj, comp):
        # a shelf compartment, the object held by its outer end (a pan's handle): slid in
        # from the open side, not lowered onto the board above
        yield from slide_in.slide_in(ctx, obj, comp)
        return
    from pipeline.policies.scripted import lay_down  # builds on this module's `place_at`

    if lay_down.too_tall(ctx, obj, target):  # it would stand too high in a shallow drawer
        yield from lay_down.stand_and_tip(ctx, obj, target)
        return
    xy, _, turn = _place_choice(ctx, obj, target)
    if shift is not None:
        xy = xy - shift
    yield from place_at(ctx, obj, xy, support_ceiling(ctx.scene.env, target), stand=stand, turn=turn)


def sweep_clearance(s: Scene, a: np.ndarray, b: np.ndarray, corridor_m: float, exclude: set[str]) -> float:
    """Highest top the hand (`corridor_m` either side) passes over between xy `a` and `b`,
    away from both ends: there it rises and comes down vertically, beside what stands there
    already, so only what lies in between needs lifting over."""
    d = np.asarray(b, dtype=float)[:2] - np.asarray(a, dtype=float)[:2]
    n = float(np.linalg.norm(d))
    if n <= 2 * corridor_m:
        return s.table_height()
    u = d / n * corridor_m
    return s.path_clearance(np.asarray(a[:2]) + u, np.asarray(b[:2]) - u, corridor_m, exclude)


def upright_hold(s: Scene, obj: str) -> tuple[np.ndarray, float] | None:
    """For an upright-standing object that tilted in the hand (a moka pot held by its
    handle swings about the fingers' axis): the grip site relative to the body, and its
    height above the object's bottom, as they will be once the object stands upright
    again. None when it is not tilted (or lies on its side: then it is put down as held)."""
    from pipeline.policies.scripted.grasps import object_frame_boxes

    boxes, body, rot, _ = object_frame_boxes(s, obj)
    if not np.cos(np.radians(STAND_MAX_TILT)) < rot[2, 2] < np.cos(np.radians(STAND_MIN_TILT)):
        return None
    g = (s.eef() - body) @ rot  # grip site in the object's frame
    heading = float(np.arctan2(rot[1, 0], rot[0, 0]))
    c, si = np.cos(heading), np.sin(heading)
    upright = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    return upright @ g, float(g[2] - boxes[:, 0, 2].min())


def place_at(ctx: Ctx, obj: str, xy: np.ndarray, below: float = np.inf, stand: bool = False,
             turn: float = 0.0, corridor_m: float = 0.0) -> Plan:
    """Carry the held object so its body comes down at `xy` on whatever supports it there
    (ignoring boxes whose top is at or above `below`), release, retreat. `stand`: an
    upright object that tilted in the hand is lowered as if it stood upright, so its low
    edge meets the support first and the pressing turns it upright in the fingers before
    they open (released tilted, a pot falls over). `turn` (rad): the hand turns the object
    about the vertical on the way (a long object along a drawer). `corridor_m`: half width
    of the path kept clear below the carried object between its ends (`sweep_clearance`),
    if wider than the object's own (the recovery expert's put-aside keeps the whole hand
    clear; 0 keeps the plain path)."""
    s = ctx.scene
    env = s.env
    eef = s.eef()
    body = env.object_pose(obj)[0]
    box = s.box(obj)
    hold = eef - body  # grip site relative to the object body, kept while carrying
    bottom = eef[2] - box.lo[2]  # grip site above the object's bottom
    carry_bottom, gap = bottom, 0.015
    up = upright_hold(s, obj) if stand else None
    if up is not None:  # down to just above the support: the low edge presses it upright
        hold, bottom = up
        gap = STAND_GAP
    c, sn = np.cos(turn), np.sin(turn)
    hold[:2] = np.array([[c, -sn], [sn, c]]) @ hold[:2]  # (turned with the hand about the grip site)
    size, shift = _carried_foot(s, obj, turn)
    radius = 0.6 * float(min(size[0], size[1])) / 2
    offset_xy = ctx.noise.place_offset()[:2]
    dest = np.asarray(xy, dtype=float)[:2] + offset_xy
    foot = dest + shift
    support = s.support_top(foot, radius, {obj}, below=below)
    offset_z = abs(ctx.noise.place_offset()[2])
    ctx.note(place_offset=[offset_xy[0], offset_xy[1], offset_z])
    release_z = support + gap + bottom + offset_z
    clear = s.path_clearance(box.centre, foot, radius, {obj})
    if corridor_m > radius:
        clear = max(clear, sweep_clearance(s, box.centre, foot, corridor_m, {obj}))
    lift_z = clear + CARRY_CLEARANCE + max(bottom, carry_bottom)
    goal = np.array([dest[0] + hold[0], dest[1] + hold[1], release_z])
    yaw = ctx.yaw_hold + turn
    yield from travel(ctx, goal, yaw, 1.0, max(lift_z, release_z + 0.05))
    if turn != 0:  # finish turning before going down (the hand turns slower than it travels)
        ctx.yaw_hold = yaw  # the release and retreat keep the turned yaw
        yield ctx.move(s.eef(), gripper=1.0, yaw=yaw, tol=0.02, rot_tol=0.05, max_steps=30, label="turn")
    if not carried(s, obj):
        ctx.events.append(f"dropped:{obj}")
        if ctx.truth is not None:
            ctx.truth.end_hand(obj, False)
        return
    t = ctx.noise.timing()
    ctx.note(release_timing=t)
    early = {"switch_gripper": -1.0, "switch_dist": 0.006 * -t} if t < 0 else {}
    # (stood up: the pot's low edge on the support stops the hand ~1 cm short of the goal;
    # a wider tolerance lets go there instead of pressing out the step limit)
    yield ctx.move(goal, gripper=1.0, speed=0.5, yaw=yaw, tol=0.01 if up is None else STAND_TOL, max_steps=60,
                   label="lower", **early)
    yield Grip(-1.0, ctx.open_steps + max(t, 0), label="open")
    yield ctx.move(s.eef() + [0, 0, 0.08], yaw=yaw, tol=0.02, label="retreat")


def pick_place(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    _, obj, target = conjunct
    s = ctx.scene
    for _ in range(ctx.max_attempts):
        if s.satisfied(conjunct):
            return
        ctx.begin("pick_place", conjunct, obj, target)
        if not carried(s, obj):
            yield from free_hand(ctx)
            yield from grasp(ctx, obj, destination(ctx, obj, target))
            if not carried(s, obj):
                ctx.events.append(f"missed_grasp:{obj}")
                if ctx.truth is not None:  # held for a while, then gone: a lost grasp, not a miss
                    ctx.truth.end_hand(obj, False)
                continue
        yield from place(ctx, obj, target)
        if ctx.truth is not None:  # a no-op when place already ended the attempt
            ctx.truth.end_hand(obj, s.satisfied(conjunct))
        if not s.satisfied(conjunct) and not carried(s, obj):
            ctx.events.append(f"misplaced:{obj}")
