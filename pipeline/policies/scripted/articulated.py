"""Skills for articulated parts: drawers (slide joints), doors (hinges) and stove knobs.

Inputs: a `Ctx` and a conjunct naming a region of a fixture (`wooden_cabinet_1_top_region`)
or a fixture (`microwave_1`, `flat_stove_1`). The part's joint, its world axis and its
handle are read from the live model: the handle is the part's outermost collision box
along the opening direction. Opening a drawer hooks the fingers behind the handle bar
and pulls; closing pushes the front; doors close by sweeping the door panel around its
hinge. Knobs live in `knobs.py`.
LIBERO convention (its articulated objects): the range end of larger magnitude is "open"
/ "on"; a cabinet counts as closed only slightly past zero, so closing pushes past it.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.goal import Predicate
from pipeline.policies.scripted.motion import Ctx, Plan, free_hand, travel
from pipeline.policies.scripted.notes import Outcome
from pipeline.policies.scripted.primitives import Grip
from pipeline.sim import SimEnv
from pipeline.sim.facts import JointKind

FINGER_HALF = 0.01  # half thickness of a closed finger pair along the closing axis
LOW_DRAWER_M = 0.08  # a handle lower than this over the table: push with a pitched fist
PUSH_PITCH = 0.9  # radians from straight down, towards the push


def part_joint(env: SimEnv, name: str) -> str | None:
    if env.is_region(name):
        r = env.region(name)
        if r.joints:
            return r.joints[0]
        name = r.parent or ""
    if name in env.fixture_names or name in env.object_names:
        joints = [j for j in env.fixture_joints(name) if env.joint_frame(j).kind in (JointKind.SLIDE, JointKind.HINGE)]
        if len(joints) == 1:
            return joints[0]
    return None


def openable(env: SimEnv, region: str) -> str | None:
    """What must be open before something goes into `region` (it or its parent), if anything."""
    if not env.is_region(region):
        return None
    r = env.region(region)
    if r.joints:
        return region
    parent = r.parent
    if parent and part_joint(env, parent) and env.joint_frame(part_joint(env, parent)).kind == JointKind.HINGE:
        return parent
    return None


def close_lower_first(env: SimEnv, steps: list[tuple[str, ...]]) -> list[tuple[str, ...]]:
    """`steps` with a drawer to close moved before a drawer above it to open: the opened
    one would stick out over the lower one's front, in the way of the push (and be pushed
    shut itself)."""
    def slide_floor(name: str) -> float | None:
        joint = part_joint(env, name)
        if joint is None or env.joint_frame(joint).kind != JointKind.SLIDE:
            return None
        return float(env.joint_part_boxes(joint)[:, 0, 2].min())

    out = list(steps)
    for c in steps:
        zc = slide_floor(c[1]) if c[0] == Predicate.CLOSE else None
        if zc is None:
            continue
        above = [i for i, o in enumerate(out) if o[0] == Predicate.OPEN and (zo := slide_floor(o[1])) is not None and zo > zc]
        if above and above[0] < out.index(c):
            out.remove(c)
            out.insert(above[0], c)
    return out


def is_closed_enough(env: SimEnv, name: str) -> bool:
    """True while `name` is not open (by LIBERO's own predicate)."""
    return not env.object_state(name).is_open()


def open_sign(rng: np.ndarray) -> float:
    return -1.0 if abs(rng[0]) > abs(rng[1]) else 1.0


def handle_box(env: SimEnv, joint: str, pull: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Outermost box of the moving part along `pull`, the world axis index, and its sign."""
    k = int(np.argmax(np.abs(pull[:2])))
    s = float(np.sign(pull[k]))
    boxes = env.joint_part_boxes(joint)
    front = [b[1, k] if s > 0 else -b[0, k] for b in boxes]
    return boxes[int(np.argmax(front))], k, s


def _operate_part(ctx: Ctx, conjunct: tuple[str, ...], opening: bool) -> Plan:
    env = ctx.scene.env
    joint = part_joint(env, conjunct[1])
    if joint is None:
        raise ValueError(f"{conjunct}: no joint to {'open' if opening else 'close'} in task {env.task.task_id}")
    for _ in range(ctx.max_attempts):
        state = env.object_state(conjunct[1])
        if state.is_open() if opening else state.is_close():
            return
        ctx.begin("open" if opening else "close", conjunct, conjunct[1])
        if env.joint_frame(joint).kind == JointKind.SLIDE:
            yield from pull_drawer(ctx, joint) if opening else _push_drawer(ctx, joint)
        else:
            yield from _swing_door(ctx, joint, opening=opening)
        if ctx.truth is not None:
            done = state.is_open() if opening else state.is_close()
            ctx.end(Outcome.ACHIEVED if done else Outcome.HALF_OPEN, f"{joint} at {env.joint_frame(joint).qpos:.3f}")


def open_part(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    return _operate_part(ctx, conjunct, opening=True)


def close_part(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    return _operate_part(ctx, conjunct, opening=False)


def pull_drawer(ctx: Ctx, joint: str, reach_speed: float = 0.4, pull_speed: float = 0.5) -> Plan:
    """Tilt the hand to point at the drawer, fingers above and below the handle bar, grip, pull.
    `reach_speed`, `pull_speed`: of the reach to the handle and of the pull (the plain
    expert's are slow and sure; the recovery expert, on a budget, moves faster)."""
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    sign = open_sign(fr.range)
    pull = fr.axis * sign
    pull = pull / np.linalg.norm(pull)
    box, k, d = handle_box(env, joint, pull)
    front = box[1, k] if d > 0 else box[0, k]
    back = box[0, k] if d > 0 else box[1, k]
    offset = ctx.noise.grasp_offset() * [0.5, 0.5, 0.5]
    ctx.note(grasp_offset=offset)
    pos = (box[0] + box[1]) / 2 + offset
    pos[k] = (front + back) / 2 - d * 0.003
    approach = -np.array([pull[0], pull[1], 0.0]) / np.linalg.norm(pull[:2])
    yaw = 0.0 if k == 1 else np.pi / 2
    yield from free_hand(ctx)
    ready = pos.copy()
    ready[k] = front + d * 0.12
    ready_hi = ready + [0, 0, 0.06]
    yield from travel(ctx, ready_hi, 0.0, -1.0, s.path_clearance(s.eef(), ready_hi, 0.06, set()) + 0.07)
    ctx.yaw_hold, ctx.approach_hold = yaw, approach
    yield ctx.move(ready, yaw=yaw, approach=approach, tol=0.012, rot_tol=0.12, max_steps=60, label="tilt")
    # half-close (the gripper command ramps 0.25 per step; 0 holds it): the fingers then
    # pass between neighbouring drawers' handles, 7 cm apart
    yield Grip(-1.0, 5, label="open_fully")
    yield Grip(1.0, 3, label="half_close")
    yield ctx.move(pos, gripper=0.0, speed=reach_speed, yaw=yaw, approach=approach, tol=0.006, max_steps=50,
                   label="reach_handle")
    t = ctx.noise.timing()
    ctx.note(grasp_timing=t)
    yield Grip(1.0, ctx.close_steps + max(t, 0), label="grip_handle")
    u = sign * env.joint_frame(joint).qpos  # how open it is now
    full = float(np.max(np.abs(fr.range)))
    target = s.eef() + pull * (full - u + 0.01)
    yield ctx.move(target, gripper=1.0, speed=pull_speed, yaw=yaw, approach=approach, tol=0.01, max_steps=60, label="pull")
    yield Grip(-1.0, ctx.open_steps, label="let_go")
    yield ctx.move(s.eef() + pull * 0.06, yaw=yaw, approach=approach, tol=0.015, max_steps=30, label="back_off")
    ctx.yaw_hold, ctx.approach_hold = 0.0, None
    yield ctx.move(s.eef() + [0, 0, 0.06], tol=0.02, rot_tol=0.15, max_steps=40, label="untilt")


def front_panel(env: SimEnv, joint: str, k: int, d: float) -> np.ndarray:
    """The drawer's front panel: the outermost of the part's boxes that span most of the
    drawer's width (the handle and its posts are narrow)."""
    boxes = env.joint_part_boxes(joint)
    width = boxes[:, 1, 1 - k] - boxes[:, 0, 1 - k]
    wide = boxes[width > 0.6 * width.max()]
    front = [b[1, k] if d > 0 else -b[0, k] for b in wide]
    return wide[int(np.argmax(front))]


def _push_drawer(ctx: Ctx, joint: str) -> Plan:
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    sign = open_sign(fr.range)
    pull = fr.axis * sign
    box, k, d = handle_box(env, joint, pull)
    if (box[0, 2] + box[1, 2]) / 2 < s.table_height() + LOW_DRAWER_M:
        yield from _push_low_drawer(ctx, joint)
        return
    front = box[1, k] if d > 0 else box[0, k]
    pos = (box[0] + box[1]) / 2
    pos[k] = front + d * 0.035
    # the palm is 20 cm long along the closing axis: turn it across the push direction so
    # it does not reach the cabinet face above the drawer before the fingers push it shut
    yaw = fist_yaw(ctx, np.pi / 2 if k == 1 else 0.0)
    ctx.yaw_hold = yaw
    # the fist closes on the way (travel's moves command the gripper shut), not before it:
    # close_steps sooner, and the fingers are shut long before the face
    hover = pos + [0, 0, 0.08]
    yield from travel(ctx, hover, yaw, 1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
    yield ctx.move(pos, gripper=1.0, speed=0.6, yaw=yaw, tol=0.01, max_steps=50, label="face_drawer")
    u = sign * env.joint_frame(joint).qpos
    target = pos.copy()
    target[k] = front + d * FINGER_HALF - d * (u + 0.025)
    yield ctx.move(target, gripper=1.0, speed=0.6, yaw=yaw, tol=0.008, max_steps=60, label="push")
    yield ctx.move(s.eef() + pull * 0.04, gripper=1.0, yaw=yaw, tol=0.015, max_steps=20, label="back_off")
    yield ctx.move(s.eef() + [0, 0, 0.08], gripper=1.0, yaw=yaw, tol=0.02, max_steps=30, label="retreat")


def fist_yaw(ctx: Ctx, yaw: float) -> float:
    """`yaw`, or for a recovery context (`Ctx.fist_wrist_free`) whichever of yaw, yaw +- pi
    leaves the wrist's last joint farthest inside its limits once the hand has turned there
    the short way (watched: a fist turned to its fixed yaw wound joint 7 from 2.6 onto its
    2.9 limit, and the arm flailed 130 steps before the push)."""
    if not ctx.fist_wrist_free:
        return yaw
    return max((yaw, yaw - np.pi, yaw + np.pi),
               key=lambda y: wrist_room(ctx.scene, float((y - ctx.yaw_hold + np.pi) % (2 * np.pi) - np.pi)))


def wrist_room(s, turn: float) -> float:
    """Radians the wrist's last joint stays inside its limits once a hand pointing down has
    turned its yaw by `turn` (it turns about -z: the joint turns the other way)."""
    q, limits = s.env.arm_joints()
    lo, hi = limits[6]
    q7 = q[6] - turn
    return min(q7 - lo, hi - q7)


def fist_into(pull: np.ndarray, pitch: float) -> np.ndarray:
    """Pointing axis of a fist pitched `pitch` radians from straight down toward a drawer
    whose opening direction is `pull` (into its face: the wrist trails behind)."""
    push = -np.array([pull[0], pull[1], 0.0]) / np.linalg.norm(pull[:2])
    return push * np.sin(pitch) + np.array([0.0, 0.0, -1.0]) * np.cos(pitch)


def _push_low_drawer(ctx: Ctx, joint: str) -> Plan:
    """A drawer just over the table (the white cabinet's bottom one): a top-down fist at
    its handle brings the forearm down onto the cabinet's top edge before the drawer is
    shut. So the fist comes down close to the front panel, just over the handle bar (clear
    of whatever stands in front of the handle), pitched to point into the drawer (the
    wrist trails behind, the forearm stays off the cabinet), and pushes past closed."""
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    sign = open_sign(fr.range)
    pull = fr.axis * sign
    box, k, d = handle_box(env, joint, pull)
    panel = front_panel(env, joint, k, d)
    face = panel[1, k] if d > 0 else panel[0, k]
    part_top = float(env.joint_part_boxes(joint)[:, 1, 2].max())
    pos = (box[0] + box[1]) / 2
    # fingertips (~1 cm below the grip site) over the handle bar, under the part's top
    pos[2] = max(part_top - 0.012, box[1, 2] + 0.02)
    pos[k] = face + d * (FINGER_HALF + 0.01)
    yaw = fist_yaw(ctx, np.pi / 2 if k == 1 else 0.0)  # the palm's long side across the push
    point = fist_into(pull, PUSH_PITCH)
    ctx.yaw_hold = yaw
    # the fist closes on the way, as _push_drawer's
    hover = pos + [0, 0, 0.08]
    yield from travel(ctx, hover, yaw, 1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
    ctx.approach_hold = point
    # pitch the fist and line it up over the gap in front of the panel before coming down:
    # a diagonal descent catches the fingertips on the panel's top edge
    yield ctx.move(hover, gripper=1.0, yaw=yaw, approach=point, tol=0.006, rot_tol=0.15, max_steps=40, label="pitch")
    yield ctx.move(pos, gripper=1.0, speed=0.6, yaw=yaw, approach=point, tol=0.01, max_steps=50, label="face_drawer")
    u = sign * env.joint_frame(joint).qpos
    target = pos.copy()
    target[k] = face + d * FINGER_HALF - d * (u + 0.03)  # past closed: LIBERO's `close` is qpos beyond 0
    yield ctx.move(target, gripper=1.0, speed=0.6, yaw=yaw, approach=point, tol=0.008, max_steps=60, label="push")
    yield ctx.move(s.eef() + pull * 0.04, gripper=1.0, yaw=yaw, approach=point, tol=0.015, max_steps=20,
                   label="back_off")
    ctx.approach_hold = None
    yield ctx.move(s.eef() + [0, 0, 0.08], gripper=1.0, yaw=yaw, tol=0.02, max_steps=30, label="retreat")


def _swing_door(ctx: Ctx, joint: str, opening: bool) -> Plan:
    """Sweep a hinged panel with a closed hand pressing on its face, in small arcs."""
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    sign = open_sign(fr.range)
    goal_q = fr.range[0] if sign < 0 else fr.range[1]
    goal_q = 0.8 * goal_q if opening else -sign * 0.05
    q = fr.qpos
    boxes = env.joint_part_boxes(joint)
    anchor, axis = fr.anchor, fr.axis
    centres = (boxes[:, 0] + boxes[:, 1]) / 2
    radial = centres[:, :2] - anchor[:2]
    far = int(np.argmax(np.linalg.norm(radial, axis=1)))
    r_far = float(np.linalg.norm(radial[far]))
    direction = radial[far] / max(r_far, 1e-6)
    z = float(centres[far, 2])
    dq = goal_q - q
    spin = np.sign(dq) * np.sign(axis[2])  # + = counter-clockwise seen from above
    tangent = spin * np.array([-direction[1], direction[0]])
    lever = anchor[:2] + direction * 0.75 * r_far
    start = np.array([*(lever - tangent * 0.06), z])
    # the fist closes on the way, as _push_drawer's
    hover = start + [0, 0, 0.1]
    yield from travel(ctx, hover, 0.0, 1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
    yield ctx.move(start, gripper=1.0, speed=0.6, tol=0.012, max_steps=50, label="face_door")
    n = max(2, int(np.ceil(abs(dq) / 0.25)))
    for i in range(1, n + 1):
        a = spin * abs(dq) * i / n
        c, si = np.cos(a), np.sin(a)
        dirn = np.array([c * direction[0] - si * direction[1], si * direction[0] + c * direction[1]])
        tan = spin * np.array([-dirn[1], dirn[0]])
        p = anchor[:2] + dirn * 0.75 * r_far - tan * 0.01
        yield ctx.move([p[0], p[1], z], gripper=1.0, speed=0.6, tol=0.015, max_steps=30, label="sweep")
    yield ctx.move(s.eef() + [0, 0, 0.1], gripper=1.0, tol=0.02, max_steps=30, label="retreat")
