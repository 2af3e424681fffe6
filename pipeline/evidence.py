"""Per-step simulator evidence of an episode, recomputed from its logged states.

Inputs: a built `SimEnv` of the episode's task, the episode's `states.npy` (row t = state
before action t) and its actions (`steps.parquet`). Each state is restored with
`set_state` (no physics stepping) and measured. Output: an `Evidence` (columns as numpy
arrays), written as one Parquet file in `EVIDENCE_SCHEMA` whose metadata also carries the
goal, the task's objects and fixtures, the goal's target and reference objects, and the
control rate, so the file is self-describing for rules, the characterizer and reviewers.

What each column means (one row per state, step 0 .. steps):
- gripper_opening: distance between the finger joints (m; about 0.08 open, ~0 closed on air);
  gripper_command: the gripper action applied at that step (+1 close, -1 open; last row repeats);
- grasped: the object touched by both fingers, or touched by one finger while lifted
  >= `LIFT_GRASP_M` above its start (a pinch on one pad still carries it);
- contacts: "a|b" pairs (sorted) of things touching: objects, fixtures, "robot", "table";
- displacement / lift / tilt_deg: distance, height change and rotation of each object's up
  axis relative to step 0; speed: linear speed from the free joint's qvel (m/s);
- eef_distance: grip site to each object's body origin (m); position: world xyz (m);
- goal_progress: share of goal conjuncts true (LIBERO's own predicates).
Invariant: measuring never changes the logged data; the env is left at the last state.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.atomic import write_with
from pipeline.records import EVIDENCE_SCHEMA

LIFT_GRASP_M = 0.02
_MAPS = ("displacement", "lift", "tilt_deg", "speed", "eef_distance")


@dataclass
class Evidence:
    step: np.ndarray  # (T,) int
    control_hz: int
    gripper_opening: np.ndarray
    gripper_command: np.ndarray
    grasped: list[str]
    contacts: list[list[str]]
    goal_progress: np.ndarray
    objects: list[str]
    fixtures: list[str]
    goal: list[list[str]]
    targets: list[str]  # objects the goal moves (first argument of On/In)
    references: list[str]  # objects/fixtures the goal puts things on/in or operates
    per_object: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # column -> obj -> (T,)

    @property
    def time_s(self) -> np.ndarray:
        return self.step / self.control_hz

    def __len__(self) -> int:
        return len(self.step)

    def col(self, column: str, obj: str) -> np.ndarray:
        return self.per_object[column][obj]

    def touching(self, t: int, a: str, b: str) -> bool:
        """Whether `a` and `b` touch at row `t`."""
        return contact_key(a, b) in self.contacts[t]

    def touching_what(self, t: int, obj: str) -> set[str]:
        """What touches `obj` at row `t` (the other name of each pair it is in)."""
        out = set()
        for pair in self.contacts[t]:
            a, _, b = pair.partition("|")
            if obj in (a, b):
                out.add(b if a == obj else a)
        return out

    def pair_mask(self, a: str, b: str) -> np.ndarray:
        """(T,) bool: rows where `a` and `b` touch."""
        key = contact_key(a, b)
        return np.array([key in c for c in self.contacts], dtype=bool)


def contact_key(a: str, b: str) -> str:
    """How `Evidence.contacts` names a pair touching: "a|b", the two names sorted."""
    return "|".join(sorted((a, b)))


def owner_of(name: str, known: list[str]) -> str:
    """The object/fixture a region name belongs to ('plate_1_contain_region' -> 'plate_1')."""
    if name in known:
        return name
    hits = [k for k in known if name.startswith(k + "_")]
    if hits:
        return max(hits, key=len)
    return "table" if name.startswith("main_table") or "table" in name else name


def goal_roles(goal: list[list[str]], known: list[str]) -> tuple[list[str], list[str]]:
    targets, refs = [], []
    for pred, *args in goal:
        owners = [owner_of(a, known) for a in args]
        if pred.lower() in ("on", "in") and len(owners) == 2:
            targets.append(owners[0])
            refs.append(owners[1])
        else:  # open / close / turnon / turnoff: the fixture itself is operated
            refs.extend(owners)
    return list(dict.fromkeys(targets)), list(dict.fromkeys(r for r in refs if r not in targets))


def _tilt_deg(q0: np.ndarray, q: np.ndarray) -> float:
    def up(qw):  # body z axis of a (w, x, y, z) quaternion, in world coordinates
        w, x, y, z = qw
        return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])

    c = float(np.clip(np.dot(up(q0), up(q)), -1.0, 1.0))
    return float(np.degrees(np.arccos(c)))


def _grasped(left: set[str], right: set[str], lift: dict[str, float], objects: list[str]) -> str:
    both = [o for o in objects if o in left and o in right]
    if both:
        return max(both, key=lambda o: lift[o])
    one = [o for o in objects if (o in left or o in right) and lift[o] >= LIFT_GRASP_M]
    return max(one, key=lambda o: lift[o]) if one else ""


def compute_evidence(env, states: np.ndarray, gripper_actions: np.ndarray, control_hz: int = 20) -> Evidence:
    """Measure every logged state. `gripper_actions` has one entry per step (len(states) - 1)."""
    objects, fixtures = env.object_names, env.fixture_names
    goal = [list(c) for c in env.goal]
    targets, refs = goal_roles(goal, objects + fixtures)
    n = len(states)
    cmd = np.empty(n, dtype=np.float32)
    if n > 1:
        cmd[:-1] = gripper_actions[: n - 1]
        cmd[-1] = cmd[-2]
    else:
        cmd[:] = -1.0
    cols = {c: {o: np.zeros(n, dtype=np.float32) for o in objects} for c in _MAPS}
    cols["position"] = {o: np.zeros((n, 3), dtype=np.float32) for o in objects}
    opening = np.zeros(n, dtype=np.float32)
    progress = np.zeros(n, dtype=np.float32)
    grasped, contacts = [], []
    start = {}
    for t in range(n):
        env.set_state(states[t])
        poses = env.object_poses()
        if t == 0:
            start = {o: (p.copy(), q.copy()) for o, (p, q) in poses.items()}
        speeds = env.object_speeds()
        eef, _ = env.eef_pose()
        lift = {}
        for o in objects:
            p, q = poses[o]
            p0, q0 = start[o]
            cols["displacement"][o][t] = np.linalg.norm(p - p0)
            lift[o] = float(p[2] - p0[2])
            cols["lift"][o][t] = lift[o]
            cols["tilt_deg"][o][t] = _tilt_deg(q0, q)
            cols["speed"][o][t] = speeds.get(o, 0.0)
            cols["eef_distance"][o][t] = np.linalg.norm(p - eef)
            cols["position"][o][t] = p
        opening[t] = env.gripper_opening()
        left, right = env.finger_contacts()
        grasped.append(_grasped(left, right, lift, objects))
        contacts.append(sorted(contact_key(a, b) for a, b in env.contacts()))
        conj = env.goal_conjuncts()
        progress[t] = sum(ok for _, ok in conj) / max(1, len(conj))
    return Evidence(
        step=np.arange(n), control_hz=control_hz, gripper_opening=opening, gripper_command=cmd,
        grasped=grasped, contacts=contacts, goal_progress=progress, objects=objects,
        fixtures=fixtures, goal=goal, targets=targets, references=refs, per_object=cols,
    )


def evidence_table(ev: Evidence) -> pa.Table:
    data = {
        "step": pa.array(ev.step, pa.int32()),
        "time_s": pa.array(ev.time_s, pa.float64()),
        "gripper_opening": pa.array(ev.gripper_opening, pa.float32()),
        "gripper_command": pa.array(ev.gripper_command, pa.float32()),
        "grasped": pa.array(ev.grasped, pa.string()),
        "contacts": pa.array(ev.contacts, pa.list_(pa.string())),
        "goal_progress": pa.array(ev.goal_progress, pa.float32()),
    }
    for c in _MAPS:
        rows = [[(o, float(ev.per_object[c][o][t])) for o in ev.objects] for t in range(len(ev))]
        data[c] = pa.array(rows, pa.map_(pa.string(), pa.float32()))
    rows = [[(o, ev.per_object["position"][o][t].tolist()) for o in ev.objects] for t in range(len(ev))]
    data["position"] = pa.array(rows, pa.map_(pa.string(), pa.list_(pa.float32(), 3)))
    meta = dict(EVIDENCE_SCHEMA.metadata or {})
    meta[b"evidence"] = json.dumps(
        {"control_hz": ev.control_hz, "objects": ev.objects, "fixtures": ev.fixtures, "goal": ev.goal,
         "targets": ev.targets, "references": ev.references}
    ).encode()
    return pa.table([data[f.name] for f in EVIDENCE_SCHEMA], schema=EVIDENCE_SCHEMA.with_metadata(meta))


def write_evidence(path: str | Path, ev: Evidence) -> None:
    table = evidence_table(ev)
    write_with(path, lambda p: pq.write_table(table, p))


def read_evidence(path: str | Path) -> Evidence:
    """Read an evidence file back; raises ValueError naming the file if it is not one."""
    table = pq.read_table(path)
    raw = (table.schema.metadata or {}).get(b"evidence")
    missing = [f.name for f in EVIDENCE_SCHEMA if f.name not in table.column_names]
    if raw is None or missing:
        raise ValueError(f"{path}: not a stage-2 evidence file (missing {missing or 'metadata'})")
    meta = json.loads(raw)
    cols = table.to_pydict()
    per_object = {}
    for c in _MAPS:
        per_object[c] = {o: np.zeros(table.num_rows, dtype=np.float32) for o in meta["objects"]}
        for t, row in enumerate(cols[c]):
            for o, v in row:
                per_object[c][o][t] = v
    per_object["position"] = {o: np.zeros((table.num_rows, 3), dtype=np.float32) for o in meta["objects"]}
    for t, row in enumerate(cols["position"]):
        for o, v in row:
            per_object["position"][o][t] = v
    return Evidence(
        step=np.asarray(cols["step"]), control_hz=int(meta["control_hz"]),
        gripper_opening=np.asarray(cols["gripper_opening"], dtype=np.float32),
        gripper_command=np.asarray(cols["gripper_command"], dtype=np.float32),
        grasped=list(cols["grasped"]), contacts=[list(c) for c in cols["contacts"]],
        goal_progress=np.asarray(cols["goal_progress"], dtype=np.float32), objects=meta["objects"],
        fixtures=meta["fixtures"], goal=meta["goal"], targets=meta["targets"],
        references=meta["references"], per_object=per_object,
    )
