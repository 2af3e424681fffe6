"""Motion: the hand's moves that every skill is built from, reading live state as they go.

Each function is a generator that yields `Move`/`Grip` primitives. The policy resumes it
only after the previous primitive finished and only at an action-chunk boundary, so
every decision (where the object is now, whether it is held) uses the live simulator
state. `Ctx` carries the scene, the noise and the generator's record through a plan.

Inputs: a `Ctx` (scene, noise). Invariants: positions are grip-site targets in world
coordinates; the hand points down. Layer: below the strategies and skills (`skills.py`,
`shelf.py`, ...), above the geometry (`placement.py`, `grasps.py`); it imports no skill.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from pipeline.policies.scripted.grasps import object_frame_boxes, plan_grasp
from pipeline.policies.scripted.noise import Noise
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import carried_foot, sweep_clearance
from pipeline.policies.scripted.primitives import Grip, Move, Primitive
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.stack import carried  # a stack of bowls counts as held
from pipeline.policies.scripted.truth import TruthLog

Plan = Iterator[Primitive]
HAND_CLEARANCE = 0.07  # grip site above obstacles when the hand moves empty
CARRY_CLEARANCE = 0.04  # held object's bottom above obstacles in transit
MAX_Z = 1.35  # keep targets inside the arm's comfortable workspace
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
    # a closed fist pushes alike turned by pi: choose the turn that keeps the wrist's last
    # joint off its limits (the recovery expert; the generator keeps its fixed yaw)
    fist_wrist_free: bool = False
    approach_hold: np.ndarray | None = None  # set while the hand is tilted (drawer handles)
    events: list[Note] = field(default_factory=list)  # what went wrong, in order (for reports)
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


AIM_TOL_M = 0.012  # a lowered object's body this far (xy) off where it was aimed is moved over
REAIM_LIFT_M = 0.015  # ... raised this much first, so it slides over nothing


def _reaim(ctx: Ctx, obj: str, dest: np.ndarray, goal: np.ndarray, yaw: float, tol: float) -> Plan:
    """Move a held, lowered object over by how far its body is off `dest` (xy), once."""
    s = ctx.scene
    off = np.asarray(dest, dtype=float)[:2] - s.env.object_pose(obj)[0][:2]
    if float(np.linalg.norm(off)) < AIM_TOL_M or not carried(s, obj):
        return
    over = s.eef() + [off[0], off[1], REAIM_LIFT_M]
    yield ctx.move(over, gripper=1.0, speed=0.5, yaw=yaw, tol=0.006, max_steps=20, label="reaim")
    down = np.array([over[0], over[1], goal[2]])
    yield ctx.move(down, gripper=1.0, speed=0.5, yaw=yaw, tol=tol, max_steps=20, label="lower")


def upright_hold(s: Scene, obj: str) -> tuple[np.ndarray, float] | None:
    """For an upright-standing object that tilted in the hand (a moka pot held by its
    handle swings about the fingers' axis): the grip site relative to the body, and its
    height above the object's bottom, as they will be once the object stands upright
    again. None when it is not tilted (or lies on its side: then it is put down as held)."""
    boxes, body, rot, _ = object_frame_boxes(s, obj)
    if not np.cos(np.radians(STAND_MAX_TILT)) < rot[2, 2] < np.cos(np.radians(STAND_MIN_TILT)):
        return None
    g = (s.eef() - body) @ rot  # grip site in the object's frame
    heading = float(np.arctan2(rot[1, 0], rot[0, 0]))
    c, si = np.cos(heading), np.sin(heading)
    upright = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    return upright @ g, float(g[2] - boxes[:, 0, 2].min())


def place_at(ctx: Ctx, obj: str, xy: np.ndarray, below: float = np.inf, stand: bool = False,
             turn: float = 0.0, corridor_m: float = 0.0, recheck: bool = False) -> Plan:
    """Carry the held object so its body comes down at `xy` on whatever supports it there
    (ignoring boxes whose top is at or above `below`), release, retreat. `stand`: an
    upright object that tilted in the hand is lowered as if it stood upright, so its low
    edge meets the support first and the pressing turns it upright in the fingers before
    they open (released tilted, a pot falls over). `turn` (rad): the hand turns the object
    about the vertical on the way (a long object along a drawer). `corridor_m`: half width
    of the path kept clear below the carried object between its ends (`sweep_clearance`),
    if wider than the object's own (the recovery expert's put-aside keeps the whole hand
    clear; 0 keeps the plain path). `recheck`: once lowered, the object's body is measured
    against `xy` before the fingers open, and the hand moves it over by what it is off (the
    recovery expert: a mug held by its rim hangs tilted and straightens as it is pressed
    down, and landed 3-4 cm off a plate's middle on attempt after attempt, past LIBERO's
    3 cm for `On`, each time by a different amount)."""
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
    size, shift = carried_foot(s, obj, turn)
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
        ctx.events.append(Note(Outcome.DROPPED, obj))
        if ctx.truth is not None:
            ctx.truth.end_hand(obj, False)
        return
    t = ctx.noise.timing()
    ctx.note(release_timing=t)
    early = {"switch_gripper": -1.0, "switch_dist": 0.006 * -t} if t < 0 else {}
    # (stood up: the pot's low edge on the support stops the hand ~1 cm short of the goal;
    # a wider tolerance lets go there instead of pressing out the step limit)
    lower_tol = 0.01 if up is None else STAND_TOL
    yield ctx.move(goal, gripper=1.0, speed=0.5, yaw=yaw, tol=lower_tol, max_steps=60, label="lower", **early)
    if recheck:
        yield from _reaim(ctx, obj, dest, goal, yaw, lower_tol)
    yield Grip(-1.0, ctx.open_steps + max(t, 0), label="open")
    yield ctx.move(s.eef() + [0, 0, 0.08], yaw=yaw, tol=0.02, label="retreat")
