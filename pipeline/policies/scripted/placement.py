"""Where a carried object goes down: placement geometry, no motion.

Input: a `Scene` (or, for the pure cores `best_spot`, `clearance_counter`, `turned_box`,
`widths`, plain numpy arrays and `Region`/`Box` facts). Output: numbers: the body xy a
placement aims at, how many footprint cells are blocked there, the hand turn to carry it
with, the support height under it, the height a path must clear. Nothing here moves the
robot or draws noise; the motion layer (`motion.py`) and the strategies above it read it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.policies.scripted.scene import Scene
from pipeline.sim.facts import Box, Region

REGION_INSIDE = 0.8  # fraction of a region's half extent a placed body is kept within
# a long object lying in a drawer (a toppled wine bottle, 18 cm) may fit only turned along the
# drawer: hand turns tried, least first, when no spot is clear at the object's own yaw
TURNS = (-np.pi / 4, np.pi / 4, -np.pi / 2, np.pi / 2)
LONG_RATIO = 1.8  # footprint length / width above which turns are tried
HAND_SPAN = 0.09  # the closed fingers' outer width across a held object: clear of walls and handles too
# the hand's housing above the fingers: ~20 cm along the closing axis, ~6 cm across, from
# ~7 cm over the drawer floor: off the drawer it meets the cabinet's face (it clears a low
# front wall, and the handles hanging over the drawer from above)
HOUSING_HALF, HOUSING_Z = np.array([0.03, 0.10]), 0.07

Blocked = Callable[[np.ndarray], int]  # body xy -> footprint cells over a wall or under an overhang


# ---- pure footprint geometry (numpy in, numbers out) ----------------------------------------
def region_half(region: Region) -> np.ndarray:
    """Half extents (world axes) of a region site."""
    return np.abs(region.mat) @ region.size


def widths(corners_xy: np.ndarray, n: int = 36) -> list[float]:
    """Widths of a set of xy points across `n` directions of the plane (180/n degrees apart)."""
    return [float(np.ptp(corners_xy @ [np.cos(t), np.sin(t)])) for t in np.linspace(0, np.pi, n, endpoint=False)]


def is_long_footprint(corners_xy: np.ndarray) -> bool:
    w = widths(corners_xy)
    return max(w) > LONG_RATIO * min(w)


def turned_box(corners_xy: np.ndarray, body_xy: np.ndarray, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """Size (xy) and centre relative to the body origin of the box around `corners_xy`
    after the hand turns them by `turn` about the vertical through the body."""
    c, sn = np.cos(turn), np.sin(turn)
    rel = (corners_xy - body_xy) @ np.array([[c, sn], [-sn, c]])
    lo, hi = rel.min(axis=0), rel.max(axis=0)
    return hi - lo, (lo + hi) / 2


def best_spot(region: Region, half: np.ndarray, xy: np.ndarray, others: list[Box], size: np.ndarray,
              shift: np.ndarray | None, blocked: Blocked, fine: int) -> tuple[tuple, np.ndarray]:
    """((blocked cells, crowd and distance), body xy) of the best grid point of `region`
    for a footprint of `size` (centred on the body, or `shift` from it): fewest `blocked`
    cells, then least overlap with `others` and nearest `xy`. `fine`: the axis (0, 1) of a
    drawer's slide, searched on a fine grid; -1 for no drawer."""
    drawer = bool(region.joints)
    best = None
    # a drawer leaves a window only a few mm long between its front wall and the handles
    # of the drawers above (the white cabinet's bottom drawer and a bowl): a fine grid
    # along its axis, and the object's footprint (not its body origin) kept off both
    nx, ny = (41 if fine == 0 else 7 if drawer else 11), (41 if fine == 1 else 7 if drawer else 11)
    # on a region (not in a drawer) the body must end inside it (LIBERO's `On` tests the body
    # origin against the region's extent): a spot on its very edge, where a crowded region
    # (the second moka pot beside the first) pushed it, left the body just outside
    edge = 1.0 if drawer else REGION_INSIDE
    for fx in np.linspace(-edge, edge, nx):
        for fy in np.linspace(-edge, edge, ny):
            p = region.pos[:2] + half[:2] * [fx, fy]
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


def no_walls(p: np.ndarray) -> int:
    return 0


def clearance_counter(xs: np.ndarray, ys: np.ndarray, heights: np.ndarray, floor: float, part_boxes: np.ndarray,
                      centre: np.ndarray, half: np.ndarray, edge: np.ndarray, shift: np.ndarray,
                      size: np.ndarray | None, step: float) -> Blocked:
    """The drawer's `blocked(body xy)` from a height map: `heights` (len(xs), len(ys); nan:
    nothing above the floor) ray-cast on the grid `xs` x `ys`, the drawer's own `part_boxes`
    (k, 2, 3), the footprint's rounded-box half `edge` at `shift` from the body. `size`
    (a turned footprint) also counts cells 1 cm off the region and those under the hand's
    housing (`HOUSING_HALF`) off the region where something stands higher than `HOUSING_Z`
    over the floor; None leaves both out."""
    hit = heights > floor + 0.02  # (nan: nothing above the floor there)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    # the drawer's own walls are thinner than the grid step: mark them from their boxes
    for b in part_boxes:
        if b[1, 2] > floor + 0.02:
            hit |= (gx >= b[0, 0] - step / 2) & (gx <= b[1, 0] + step / 2) & (gy >= b[0, 1] - step / 2) & (gy <= b[1, 1] + step / 2)
    high = None
    if size is not None:
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


# ---- the same, read from a live scene -------------------------------------------------------
def region_box(env, region: str) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half extents (world axes) of a region site."""
    r = env.region(region)
    return r.pos, region_half(r)


def carried_foot(s: Scene, obj: str, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """Size (xy) and centre relative to the body origin of the footprint the object comes
    down with: its box as it is, or turned by `turn` (`turned_foot`)."""
    if turn == 0:
        return s.box(obj).size[:2], box_centre_offset(s, obj)
    return turned_foot(s, obj, turn)


def turned_foot(s: Scene, obj: str, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """Size (xy) and centre relative to the body origin of the object's footprint box after
    the hand turns it by `turn` about the vertical."""
    return turned_box(s.env.object_corners(obj)[:, :2], s.env.object_pose(obj)[0][:2], turn)


def footprint_widths(s: Scene, obj: str) -> list[float]:
    """The object's footprint width across 36 directions of the plane (5 degrees apart)."""
    return widths(s.env.object_corners(obj)[:, :2])


def is_long(s: Scene, obj: str) -> bool:
    return is_long_footprint(s.env.object_corners(obj)[:, :2])


def place_choice(s: Scene, obj: str, target: str) -> tuple[np.ndarray, int, float]:
    """Where the object's body should end up (xy), how many footprint cells are blocked there,
    and the hand turn (rad) to carry it with: on an object's body or a region's centre; in a
    drawer, the point nearest its centre where the object's footprint lies inside the walls
    with open sky above (an open bottom drawer lies partly under the drawers above it and
    their handles); a long object that fits nowhere as it lies is tried turned (`TURNS`)."""
    xy = s.pos(target)[:2].copy()
    if not s.env.is_region(target):
        return xy, 0, 0.0
    r = s.env.region(target)
    drawer = bool(r.joints)
    _, half = region_box(s.env, target)
    top = r.pos[2] + half[2]
    size = s.box(obj).size[:2]
    # other objects already standing in the region (the second moka pot on a stove)
    reach = 0.5 * float(max(size))  # objects within this of the region count
    others = [s.box(o) for o in s.env.object_names if o != obj]
    others = [b for b in others if np.all(b.hi[:2] > xy - half[:2] - reach) and np.all(b.lo[:2] < xy + half[:2] + reach)]
    if s.env.region(target).parent in s.env.object_names:
        others = []  # a container object (a basket): things may share its middle
    if not drawer and not others:
        return xy, 0, 0.0
    key, spot = _spot(s, obj, r, half, top, xy, others, size, None)
    best = (key, spot, 0.0)
    if drawer and key[0] > 0 and is_long(s, obj):
        # judged again with the hand and the footprint's true extent, as it lies and turned
        best = None
        for turn in (0.0, *TURNS):
            size_t, shift_t = turned_foot(s, obj, turn)
            # the fingers close across its width at its middle and go down with it
            size_t[np.argmin(size_t)] = max(float(size_t.min()), HAND_SPAN)
            key, spot = _spot(s, obj, r, half, top, xy, others, size_t, shift_t)
            if best is None or key[0] < best[0][0]:
                best = (key, spot, turn)
            if best[0][0] == 0:
                break
    return best[1], best[0][0], best[2]


def _spot(s: Scene, obj: str, r: Region, half: np.ndarray, top: float, xy: np.ndarray, others: list[Box],
          size: np.ndarray, shift: np.ndarray | None) -> tuple[tuple, np.ndarray]:
    """`best_spot` with a drawer's clearance ray-cast from the scene."""
    drawer = bool(r.joints)
    fine = int(np.argmax(np.abs(np.asarray(s.env.joint_frame(r.joints[0]).axis[:2])))) if drawer else -1
    blocked = (drawer_clearance(s, obj, r.joints[0], r.pos[:2], half[:2], top, size, shift) if drawer
               else no_walls)
    return best_spot(r, half, xy, others, size, shift, blocked, fine)


def drawer_clearance(s: Scene, obj: str, joint: str, centre: np.ndarray, half: np.ndarray, top: float,
                     size: np.ndarray | None = None, shift: np.ndarray | None = None) -> Blocked:
    """For a drawer region: a function of the object's body xy giving how many cells of its
    footprint (a rounded box, 4 mm margin) lie over a wall or under an overhang (anything
    struck by a ray from above higher than 2 cm over the drawer floor). Heights are ray-cast
    once on a 5 mm grid. `size`/`shift`: a turned footprint (default: the object's box); with
    them the grid also covers the shifted footprint (see `clearance_counter`)."""
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
    return clearance_counter(xs, ys, heights, floor, s.env.joint_part_boxes(joint), centre, half, edge, shift,
                             size if turned else None, step)


def place_xy(s: Scene, obj: str, target: str) -> np.ndarray:
    return place_choice(s, obj, target)[0]


def place_room(s: Scene, obj: str, target: str) -> bool:
    """Whether `target` has a spot where `obj` goes in clear of walls and overhangs."""
    return place_choice(s, obj, target)[1] == 0


def inside_region(env, target: str, xy: np.ndarray) -> np.ndarray:
    """`xy` moved the least that keeps a body origin within REGION_INSIDE of the region
    `target`'s half extent (LIBERO's `On` tests the body origin); unchanged for a non-region."""
    if not env.is_region(target):
        return xy
    r = env.region(target)
    half = np.abs(r.mat @ r.size)[:2] * REGION_INSIDE
    return np.clip(xy, r.pos[:2] - half, r.pos[:2] + half)


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
    top = r.pos[2] + float(np.abs(r.mat @ r.size)[2])
    return top if r.joints else top + 0.03


def destination(s: Scene, obj: str, target: str) -> np.ndarray:
    """(x, y, support top) where the object's body should come to rest (no noise)."""
    dest, _, turn = place_choice(s, obj, target)
    size, shift = carried_foot(s, obj, turn)
    foot = dest + shift
    below = support_ceiling(s.env, target)
    radius = 0.6 * float(min(size[0], size[1])) / 2
    return np.array([dest[0], dest[1], s.support_top(foot, radius, {obj}, below=below)])


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
