"""Skill: push an object clear of a wall before grasping it.

An object lying against a neighbour (a pudding against the wall of the basket it goes into)
can leave no grasp candidate clear: every yaw puts a finger or the palm into the wall, and
each descent stops on the wall's top (measured: four attempts, then the horizon). The ray
test of `checks.tip_blockers` sees the fingertips only; `palm_block` also tests the hand's
boxes (palm and fingers) against the neighbours' collision boxes. When no candidate is
clear, `push_plan` finds the shortest push by the closed fist that frees one (the object
slides along the wall, away from it), and `push` does it; the grasp is then chosen again
from the live scene.

Geometry is planned by translating the object (its grasp candidates move with it); the
push itself reads nothing but the plan, and the caller replans from the live state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.hand import FINGER_REACH, Grasp, closing_axis, closing_yaw
from pipeline.policies.scripted.motion import HAND_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.long_grasp import slide_clear, slides
from pipeline.policies.scripted.scene import Scene, robot_base

# the hand at a grip site pointing down, in (along the closing axis, across it, up) from the
# grip site: the palm's box reaches ~10 cm either way from ~5 cm above the site (see
# grasps.blocked_depth), the wrist above it is narrower; an open finger is ~2 cm square,
# its tip ~1.2 cm below the site
PALM = ((-checks.PALM_REACH_M, checks.PALM_REACH_M), (-checks.PALM_HALF_M, checks.PALM_HALF_M), (0.05, 0.12))
WRIST = ((-0.04, 0.04), (-0.04, 0.04), (0.12, 0.30))
FINGER = ((-0.01, 0.01), (-0.01, 0.01), (-0.012, 0.05))
FIST = ((-0.015, 0.015), (-0.012, 0.012), (-0.012, 0.05))  # both fingers closed together
TRIES = checks.GRASP_TRIES  # grasp candidates looked at
DIRECTIONS = 12  # push directions, evenly round
OFFSETS = (0.0, -0.01, 0.01)  # the fist's contact point across the push, from the object's middle
FACE_MARGIN_M = 0.005  # ... kept this far inside the object's edge
LENGTHS = (0.05, 0.08, 0.11, 0.14)  # push lengths, shortest first
SLIP_M = 0.02  # the object may lag the fist by this much (it turns, slides): planned clear without it
GAP_M = 0.02  # the fist comes down this far behind the object
PUSH_Z = 0.025  # grip site above the table while pushing (fingertips ~1.3 cm above it)
FREE_PAD = 0.004  # the hand keeps this far from neighbours' boxes
# ... but the first attempt gives up the rays' grasp only for a palm this deep in a fixture
# (an upright bottle's palm end grazes the rack's lip by a few mm, and its grasp is fine)
FIXTURE_DEPTH_M = 0.01
ABOVE_TABLE = 0.005  # boxes lower than this above the table top are the table (or a mat)


@dataclass(frozen=True)
class Push:
    start: np.ndarray  # grip site where the fist comes down behind the object
    end: np.ndarray  # ... and where the push ends
    yaw: float  # hand yaw: the palm's length along the push
    shift: np.ndarray  # the object's planned horizontal shift (x, y, 0)


def _boxes(scene: Scene, obj: str) -> list[tuple[str, np.ndarray]]:
    """World-aligned collision boxes of everything but `obj` above the table."""
    top = scene.table_height() + ABOVE_TABLE
    return [(n, b) for n, b in scene.obstacle_boxes({obj}) if b[1, 2] > top]


@dataclass(frozen=True)
class Solids:
    """Oriented collision boxes of a scene's things but one: owners, centres (n, 3), unit
    axes as rows (n, 3, 3), half sizes (n, 3)."""

    names: list[str]
    centres: np.ndarray
    axes: np.ndarray
    halves: np.ndarray


def _solids(scene: Scene, obj: str) -> Solids:
    """Everything but `obj` above the table, as oriented boxes: a tilted slat's world-aligned
    box covers the air beside it (a rack's slats overlapped an upright bottle's palm box
    that way, and its grasp was fine)."""
    top = scene.table_height() + ABOVE_TABLE
    names, centres, axes, halves = [], [], [], []
    for name in scene.things():
        if name == obj:
            continue
        for c in scene.env.object_corners(name).reshape(-1, 8, 3):
            if c[:, 2].max() <= top:
                continue
            # corners run over signs (i, j, k) in (-1, 1)^3, k fastest (SimEnv.object_corners)
            edges = np.array([c[4] - c[0], c[2] - c[0], c[1] - c[0]]) / 2
            half = np.linalg.norm(edges, axis=1)
            names.append(name)
            centres.append(c.mean(axis=0))
            axes.append(np.where(half[:, None] > 1e-9, edges / np.maximum(half, 1e-9)[:, None], np.eye(3)))
            halves.append(half)
    return Solids(names, np.array(centres).reshape(-1, 3), np.array(axes).reshape(-1, 3, 3),
                  np.array(halves).reshape(-1, 3))


def _depths(pos: np.ndarray, yaw: float, part, solids: Solids, along_off: float = 0.0) -> np.ndarray:
    """How far (m) the hand `part` (a box in hand coordinates, moved `along_off` along the
    closing axis) at grip site `pos` and `yaw` goes into each solid: the least overlap over
    the separating axes (negative: the gap, when apart)."""
    (a0, a1), (c0, c1), (z0, z1) = part
    ax = closing_axis(yaw)
    hand_axes = np.array([ax, [-ax[1], ax[0], 0.0], [0.0, 0.0, 1.0]])
    hand_half = np.array([a1 - a0, c1 - c0, z1 - z0]) / 2
    hand_centre = pos + hand_axes.T @ np.array([(a0 + a1) / 2 + along_off, (c0 + c1) / 2, (z0 + z1) / 2])
    d = solids.centres - hand_centre
    depth = np.full(len(solids.names), np.inf)
    tests = [np.broadcast_to(t, d.shape) for t in hand_axes]
    tests += [solids.axes[:, i] for i in range(3)]
    tests += [np.cross(u, solids.axes[:, i]) for u in hand_axes for i in range(3)]
    for t in tests:
        n = np.linalg.norm(t, axis=1)
        ok = n > 1e-6
        t = t / np.maximum(n, 1e-6)[:, None]
        solid_reach = np.sum(np.abs(np.einsum("nij,nj->ni", solids.axes, t)) * solids.halves, axis=1)
        reach = np.abs(t @ hand_axes.T) @ hand_half + solid_reach
        gap = reach - np.abs(np.sum(d * t, axis=1))
        depth = np.where(ok, np.minimum(depth, gap), depth)
    return depth


def palm_block(scene: Scene, obj: str, g: Grasp, shift: np.ndarray | None = None, pad: float = FREE_PAD,
               solids: Solids | None = None) -> list[str]:
    """Neighbours of `obj` that the open hand's palm or fingers go into (or come within `pad`
    of; a negative `pad`: go deeper into than that) when grasping with `g` (moved by `shift`
    with the object): a palm landing on a wall's top, which the fingertip rays miss."""
    solids = _solids(scene, obj) if solids is None else solids
    depth = _hand_depth(g.pos if shift is None else g.pos + shift, g.yaw, solids)
    return sorted({n for n, dep in zip(solids.names, depth) if dep > -pad})


def _hand_depth(pos: np.ndarray, yaw: float, solids: Solids) -> np.ndarray:
    """How far the open hand at grip site `pos` goes into each solid: the deepest of its
    palm, wrist and two fingers (`_depths`)."""
    depth = np.maximum(_depths(pos, yaw, PALM, solids), _depths(pos, yaw, WRIST, solids))
    for sg in (-1, 1):
        depth = np.maximum(depth, _depths(pos, yaw, FINGER, solids, sg * FINGER_REACH))
    return depth


def _candidates(scene: Scene, obj: str, dest: np.ndarray | None, attempt: int):
    """(choice, grasp) of the candidates from `attempt` on, each slid clear along a long
    object first, then slid the other ways (`long_grasp`)."""
    for k in range(attempt, attempt + TRIES):
        g = plan_grasp(scene, obj, dest, k)
        for h in [slide_clear(scene, obj, g), *slides(scene, obj, g)]:
            yield k, h


def _clear(scene: Scene, obj: str, g: Grasp, solids: Solids, shift: np.ndarray | None = None) -> bool:
    moved = g if shift is None else Grasp(pos=g.pos + shift, yaw=g.yaw, rim=g.rim)
    return not palm_block(scene, obj, g, shift, solids=solids) and not checks.tip_blockers(scene, obj, moved, set())


def palm_clear(scene: Scene, obj: str, dest: np.ndarray | None, attempt: int) -> tuple[int, Grasp] | None:
    """A grasp candidate (and its grasp, slid along a long object if need be) whose fingers
    and palm land clear of neighbours, or None. The first attempt trusts the fingertip rays
    when they see a clear candidate whose palm meets no fixture (a palm's edge brushing a
    light object only nudges it; a rack or a cabinet stops the descent); after a failed
    attempt the palm counts whatever it meets. A rim grasp's first attempt always trusts the
    rays: the palm's box, the open hand's full span, is coarse over a rim (a bowl beside
    KITCHEN_SCENE10's cabinet looked 1 cm into it, and the grasp chosen instead dropped the
    bowl twice, at zero noise, where the rays' grasp finished the task)."""
    solids = _solids(scene, obj)
    rays = checks.clear_grasp_choice(scene, obj, dest, attempt, TRIES)
    g = slide_clear(scene, obj, plan_grasp(scene, obj, dest, rays))
    if (attempt == 0 and not checks.tip_blockers(scene, obj, g, set())
            and (g.rim or not set(palm_block(scene, obj, g, pad=-FIXTURE_DEPTH_M, solids=solids))
                 & set(scene.env.fixture_names))):
        return rays, g
    return next(((k, h) for k, h in _candidates(scene, obj, dest, attempt) if _clear(scene, obj, h, solids)), None)


def _fixture_depth(scene: Scene, obj: str, g: Grasp, solids: Solids) -> float | None:
    """How deep (m) the open hand of `g` goes into fixtures, when it comes clear of
    everything else (fingertip rays and palm); None when it does not."""
    if checks.tip_blockers(scene, obj, g, set()):
        return None
    fixtures = set(scene.env.fixture_names)
    depth = _hand_depth(g.pos, g.yaw, solids)
    if any(d > -FREE_PAD for n, d in zip(solids.names, depth) if n not in fixtures):
        return None  # (as `palm_block` with its pad)
    return max([float(d) for n, d in zip(solids.names, depth) if n in fixtures], default=0.0)


def palm_graze(scene: Scene, obj: str, dest: np.ndarray | None, attempt: int) -> tuple[int, Grasp] | None:
    """When no candidate is clear and no push frees one: of the candidates (and their slides
    along a long object) clear of all but fixtures, the one whose hand grazes them least, if
    no deeper than FIXTURE_DEPTH_M (the first attempt's own allowance); else None. A bottle
    lying between the wine rack and the cabinet had no clear grasp: the rays' choice went
    2 cm into the rack and stopped on it four times (retries_exhausted), while a grasp slid
    3 cm along the bottle, its palm's end 4 mm into the box of the cabinet's edge, went
    down and held (measured: a tuning run's libero_goal scene)."""
    solids = _solids(scene, obj)
    best = None
    for k, h in _candidates(scene, obj, dest, attempt):
        depth = _fixture_depth(scene, obj, h, solids)
        if depth is not None and depth <= FIXTURE_DEPTH_M and (best is None or depth < best[0] - 1e-4):
            best = (depth, k, h)
    return None if best is None else best[1:]


def _pushed_into(scene: Scene, obj: str, shift: np.ndarray, boxes) -> bool:
    """Sliding `obj` by `shift` (and the slip beyond it) drives it into a neighbour."""
    b = scene.box(obj)
    n = float(np.linalg.norm(shift))
    u = shift / n
    for d in np.linspace(0.005, n + SLIP_M, 8):
        lo, hi = b.lo[:2] + u[:2] * d, b.hi[:2] + u[:2] * d
        for _, box in boxes:
            if box[0, 2] < b.hi[2] and np.all(box[0, :2] - FREE_PAD < hi) and np.all(lo < box[1, :2] + FREE_PAD):
                # (boxes it already overlaps, a mat it stands on, do not count)
                if not (np.all(box[0, :2] < b.hi[:2]) and np.all(b.lo[:2] < box[1, :2])):
                    return True
    return False


def _hand_path_clear(pos: np.ndarray, end: np.ndarray, yaw: float, solids: Solids) -> bool:
    for t in np.linspace(0.0, 1.0, 6):
        p = (1 - t) * pos + t * end
        if any(np.any(_depths(p, yaw, part, solids) > -FREE_PAD) for part in (FIST, PALM, WRIST)):
            return False
    return True


def push_plan(scene: Scene, obj: str, dest: np.ndarray | None,
              frees: Callable[[np.ndarray], bool] | None = None) -> Push | None:
    """The shortest push of `obj` by the fist after which some grasp candidate is clear (or,
    given `frees`, after which `frees(shift)` holds: another skill's test of its own grasp):
    the fist comes down behind it and pushes straight, the hand clear of every neighbour and
    the object driven into none; ties go to the end nearest the arm's home. None: no push
    frees it."""
    boxes, solids = _boxes(scene, obj), _solids(scene, obj)
    corners = scene.env.object_corners(obj)[:, :2]
    centre = scene.box(obj).centre
    z = scene.table_height() + PUSH_Z
    base = robot_base(scene)[:2]
    home = base + checks.HOME_XY
    if frees is None:
        cands = [plan_grasp(scene, obj, dest, k) for k in range(TRIES)]

        def frees(shift: np.ndarray) -> bool:
            return any(_clear(scene, obj, g, solids, shift) for g in cands)
    for length in LENGTHS:
        best = None
        for theta in np.arange(DIRECTIONS) * 2 * np.pi / DIRECTIONS:
            u = np.array([np.cos(theta), np.sin(theta), 0.0])
            across = np.array([-u[1], u[0], 0.0])
            shift = u * length
            end_xy = centre[:2] + shift[:2]
            if not checks.MIN_REACH_M < float(np.linalg.norm(end_xy - base)) < checks.REACH_M:
                continue
            if _pushed_into(scene, obj, shift, boxes):
                continue
            if not frees(u * (length - SLIP_M)):
                continue
            back = float((corners @ u[:2]).min())
            mid = float((corners @ across[:2]).mean())
            width = float(np.ptp(corners @ across[:2]))
            yaw = closing_yaw(u)
            # the fist stays on the object's face: an offset past its edge is taken at the edge
            # (skipping it instead hung on a float: a 3 cm pudding's 1 cm offset measured
            # 0.15 mm past 3/2 - 0.5 cm, and no push was left along the basket's wall)
            edge = max(width / 2 - FACE_MARGIN_M, 0.0)
            for off in dict.fromkeys(float(np.clip(o, -edge, edge)) for o in OFFSETS):
                start = u * (back - GAP_M - FIST[0][1]) + across * (mid + off)
                start[2] = z
                end = start + u * (GAP_M + length)
                if not _hand_path_clear(start, end, yaw, solids):
                    continue
                cost = float(np.linalg.norm(end_xy - home))
                if best is None or cost < best[0]:
                    best = (cost, Push(start=start, end=end, yaw=yaw, shift=shift))
                break
        if best is not None:
            return best[1]
    return None


def push(ctx: Ctx, obj: str, plan: Push) -> Plan:
    """Close the hand into a fist on the way, come down behind `obj`, push it along the
    plan and rise (the hand stays closed: the grasp that follows opens it on its way)."""
    s = ctx.scene
    above = plan.start + [0, 0, 0.08]
    lift_z = s.path_clearance(s.eef(), above, 0.06, set()) + HAND_CLEARANCE
    yield from travel(ctx, above, plan.yaw, 1.0, lift_z)
    yield ctx.move(above, gripper=1.0, yaw=plan.yaw, tol=0.012, rot_tol=0.1, max_steps=40, label="over_push")
    yield ctx.move(plan.start, gripper=1.0, speed=0.5, yaw=plan.yaw, tol=0.008, max_steps=40, label="fist_down")
    yield ctx.move(plan.end, gripper=1.0, speed=0.35, yaw=plan.yaw, tol=0.008, max_steps=60, label="push")
    u = plan.shift / float(np.linalg.norm(plan.shift))
    yield ctx.move(s.eef() - u * 0.02 + [0, 0, 0.08], gripper=1.0, yaw=plan.yaw, tol=0.02, max_steps=30,
                   label="push_rise")
