"""Seeded horizontal perturbation of a restored scene's free objects.

Input: the flattened MuJoCo state of a restored scene, the qpos addresses of the free
joints (`SimEnv.free_joints()`), and (seed, scene_id, trial).
Output: each free-joint object's (dx, dy) offset, drawn uniformly from
[-max_offset_m, max_offset_m]^2, and the state with those offsets added to the objects' x, y.

Invariants:
- the random stream depends only on (seed, scene_id, trial), never on the policy, the
  gripper condition or scheduling, so every policy (and both gripper conditions) meet the
  same perturbed scenes: open vs closed and policy vs policy comparisons are paired;
- objects are drawn in sorted name order, so the offsets do not depend on dict order;
- only free joints move: hinge and slide joints (drawers, doors, knobs), the robot and all
  velocities are left as they were; z and orientation are unchanged.
"""

from __future__ import annotations

import hashlib

import numpy as np


def trial_seed_sequence(seed: int, scene_id: str, trial: int) -> np.random.SeedSequence:
    scene_word = int.from_bytes(hashlib.sha256(scene_id.encode()).digest()[:8], "little")
    return np.random.SeedSequence([int(seed) & 0xFFFFFFFF, scene_word, int(trial)])


def sample_offsets(seed: int, scene_id: str, trial: int, objects: list[str],
                   max_offset_m: float) -> dict[str, tuple[float, float]]:
    """Uniform horizontal offsets per object, reproducible from (seed, scene_id, trial)."""
    rng = np.random.default_rng(trial_seed_sequence(seed, scene_id, trial))
    names = sorted(objects)
    draws = rng.uniform(-max_offset_m, max_offset_m, size=(len(names), 2))
    return {n: (float(dx), float(dy)) for n, (dx, dy) in zip(names, draws, strict=True)}


def offset_state(state: np.ndarray, qpos_addr: dict[str, int],
                 offsets: dict[str, tuple[float, float]]) -> np.ndarray:
    """A copy of a flattened state (time, qpos, qvel) with objects shifted in x and y."""
    out = np.array(state, dtype=np.float64, copy=True)
    for name, (dx, dy) in offsets.items():
        if name not in qpos_addr:
            raise KeyError(f"object {name!r} has no free joint in this scene")
        a = 1 + qpos_addr[name]  # +1: the flattened state starts with the time
        out[a] += dx
        out[a + 1] += dy
    return out


def perturb(env, seed: int, scene_id: str, trial: int, max_offset_m: float) -> dict[str, tuple[float, float]]:
    """Shift every free-joint object of the env's current state; return the offsets."""
    addr = env.free_joints()
    offsets = sample_offsets(seed, scene_id, trial, list(addr), max_offset_m)
    if max_offset_m > 0:
        env.set_state(offset_state(env.get_state(), addr, offsets))
    return offsets
