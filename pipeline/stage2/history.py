"""The pre-failure temporal history saved beside a scene.

Inputs: the task's built env, the episode's states (row t = state before action t), its
step log (STEP_SCHEMA rows) and the onset. Outputs: two compressed npz files covering the
`window` observations before the onset, every `stride`-th step ending at onset - 1, oldest
first. `step_<NNNN>_history.npz` holds what is exactly reproducible (released, checksummed):
    steps          (k,) int32            the simulator steps (k <= window; fewer near the start)
    time_s         (k,) float64
    eef_pos        (k, 3) float32        robot state at those steps (from steps.parquet)
    eef_quat       (k, 4) float32        w, x, y, z
    gripper_qpos   (k, 2) float32
    actions        (k, 7) float32        the action the policy applied at that step
    sim_states     (k, state_dim) float64
`step_<NNNN>_history_frames.npz` holds `steps`, `renderer_version` (pipeline/rendered.py) and
one (k, S, S, 3) uint8 array per camera, rendered from `sim_states`, right side up. It is kept apart because software rendering is
not bit-identical across processes (measured: ~14% of pixels differ on textured fixtures),
so it cannot be part of a byte-reproducible release; anyone can re-render it from the states.
Invariant: the onset state itself is not part of the history (it is the scene).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.atomic import write_with
from pipeline.rendered import history_stamp


def history_steps(onset: int, window: int, stride: int) -> list[int]:
    return sorted(s for s in range(onset - stride, onset - stride * window - 1, -stride) if s >= 0)


def build_history(states: np.ndarray, step_rows: dict[str, np.ndarray], onset: int, window: int,
                  stride: int, control_hz: int = 20) -> dict[str, np.ndarray]:
    """The reproducible history before `onset` (see the module docstring); no rendering."""
    steps = history_steps(onset, window, stride)
    out: dict[str, np.ndarray] = {
        "steps": np.asarray(steps, dtype=np.int32),
        "time_s": np.asarray(steps, dtype=np.float64) / control_hz,
        "sim_states": np.asarray(states[steps], dtype=np.float64).reshape(len(steps), states.shape[1]),
    }
    for name, width in (("eef_pos", 3), ("eef_quat", 4), ("gripper_qpos", 2), ("action", 7)):
        col = step_rows[name]
        key = "actions" if name == "action" else name
        out[key] = np.asarray(col[steps], dtype=np.float32).reshape(len(steps), width)
    return out


def render_frames(env, history: dict[str, np.ndarray], cameras: list[str], size: int) -> dict[str, np.ndarray]:
    """Frames of a history's states, one (k, S, S, 3) array per camera (plus `steps` and the
    renderer version)."""
    return {"steps": history["steps"], **history_stamp(), **env.render_states(history["sim_states"], cameras, size)}


def write_history(path: Path, history: dict[str, np.ndarray]) -> None:
    write_with(path, lambda p: np.savez_compressed(p, **history))
