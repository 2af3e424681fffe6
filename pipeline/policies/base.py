"""The one policy interface.

A policy sees an `Observation` and returns an action chunk (N x 7: delta end-effector
position and axis-angle rotation, then the gripper command, -1 open / +1 close). The
runner executes `chunk_size` of those actions open loop, then asks again.

Policies that plan from privileged simulator state (the scripted expert) read
`obs.sim`; image policies (openpi) declare `cameras` and get LIBERO's own frames rendered
at `image_size` (the camera resolution their convention renders at; the policy resizes
further itself), right side up. Nothing else of the simulator reaches a policy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from pipeline.sim import SimEnv, TaskSpec


@dataclass
class Observation:
    instruction: str
    step: int
    eef_pos: np.ndarray  # (3,)
    eef_quat: np.ndarray  # (4,) w, x, y, z
    gripper_qpos: np.ndarray  # (2,)
    images: dict[str, np.ndarray] = field(default_factory=dict)  # camera -> HxWx3 uint8
    # optional temporal context: e.g. the task's initial frame or pre-failure history
    context: dict[str, Any] = field(default_factory=dict)
    sim: SimEnv | None = None  # privileged access, for scripted policies only


@runtime_checkable
class Policy(Protocol):
    name: str
    cameras: tuple[str, ...]  # () for state-only policies
    image_size: int

    def reset(self, task: TaskSpec, seed: int) -> None:
        """Called at the start of every episode."""

    def act(self, obs: Observation) -> np.ndarray:
        """Return an action chunk of shape (N, 7), N >= 1."""

    def params(self) -> dict:
        """Parameters recorded with each episode (noise levels, server address, ...)."""

    def close(self) -> None: ...
