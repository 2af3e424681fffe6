"""Frames of logged states drawn from a bare compiled model, away from the environment.

A stage-1 worker renders its videos in a helper process (pipeline/stage1/render_pool.py)
that must draw exactly what `SimEnv.render_states` draws, without building LIBERO again
(seconds, and robosuite in one more process). So the worker saves its environment's
compiled model once (`save_model`: an MJB file, about 300 MB for a LIBERO scene, mostly
textures, saved in 0.1 s and loaded in 0.5 s) and sends with every episode the model
fields LIBERO's reset rewrites (`reset_fields`: the fixtures' body poses); the helper sets
time, qpos and qvel from each logged state and runs `mj_forward`, as robosuite's
`set_state_from_flattened` + `forward` do. Same model, same kinematics, same renderer:
the same pixels (tests/stage1/test_render_pool.py compares them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.sim.render import FrameRenderer

# model fields LIBERO's `_reset_internal` writes (fixture placement, bddl_base_domain.py)
RESET_FIELDS = ("body_pos", "body_quat")


def save_model(env, path: str | Path) -> None:
    """Write `env`'s compiled MuJoCo model (a `SimEnv`) as MJB to `path`."""
    import mujoco

    mujoco.mj_saveModel(env.env.sim.model._model, str(path), None)


def reset_fields(env) -> dict[str, np.ndarray]:
    model = env.env.sim.model._model
    return {name: np.array(getattr(model, name)) for name in RESET_FIELDS}


class StateRenderer:
    """Renders flattened states (time, qpos, qvel) of one saved model; reuse across episodes."""

    def __init__(self, mjb_path: str | Path):
        """`mjb_path`: the saved model (MJB), or an MJCF `.xml` (benchmarks/render_cost.py)."""
        import mujoco

        self._mujoco = mujoco
        load = mujoco.MjModel.from_xml_path if Path(mjb_path).suffix == ".xml" else mujoco.MjModel.from_binary_path
        self.model = load(str(mjb_path))
        self.data = mujoco.MjData(self.model)
        self._renderers: dict[tuple[int, str], FrameRenderer] = {}

    def renderer(self, size: int, quality: str) -> FrameRenderer:
        r = self._renderers.get((size, quality))
        if r is None:  # creating one uploads the textures: about 1.5 s, once per model
            r = self._renderers[(size, quality)] = FrameRenderer(self.model, size, quality)
        return r

    def render_states(self, states: np.ndarray, cameras: list[str], size: int, quality: str,
                      fields: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """(k, S, S, 3) uint8 frames per camera, as `SimEnv.render_states` returns them."""
        m, d = self.model, self.data
        for name, value in fields.items():
            getattr(m, name)[:] = value
        states = np.asarray(states, dtype=np.float64)
        if states.ndim != 2 or states.shape[1] != 1 + m.nq + m.nv:
            raise ValueError(f"states have shape {states.shape}, the model needs (k, {1 + m.nq + m.nv})")
        r = self.renderer(size, quality)
        frames: dict[str, list[np.ndarray]] = {cam: [] for cam in cameras}
        for state in states:
            d.time = state[0]
            d.qpos[:] = state[1 : 1 + m.nq]
            d.qvel[:] = state[1 + m.nq :]
            self._mujoco.mj_forward(m, d)
            for cam in cameras:
                frames[cam].append(r.render(d, cam))
        return {cam: np.asarray(f, dtype=np.uint8).reshape(len(states), size, size, 3) for cam, f in frames.items()}

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
