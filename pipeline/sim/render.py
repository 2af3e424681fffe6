"""Offscreen rendering straight from MuJoCo, right side up, drawing what LIBERO draws.

LIBERO renders through robosuite's `MjRenderContext` (robosuite/utils/binding_utils.py):
a scene of at most 1000 geoms, geom group 0 (robosuite's collision meshes) hidden unless
`render_collision_mesh`, groups 1-2 drawn, the model's own lights, materials and 4x
multisampling, the fixed camera, no flip (so its images are upside down). `FrameRenderer`
draws through `mujoco.Renderer` with the same scene option and scene size, and
`mujoco.Renderer` returns the image right side up: at "standard" quality a frame equals
LIBERO's `OffScreenRenderEnv` observation flipped vertically, pixel for pixel, for both
cameras and any size (tests/sim/test_libero_frames.py builds LIBERO's own environment beside
ours and compares). `RENDERER_VERSION` names this renderer; version 1 (before 2026-11-27)
drew the collision meshes over the visual ones (a green arm, a blue gripper, an olive table),
and every frame file records the version that made it.

It renders without robosuite's offscreen renderer, so physics-only rollouts stay cheap and
frames can be rendered later from logged states.

Quality: "standard" is LIBERO's frame, which policies are trained on: the only quality
for policy inputs and training data. "fast" is the same scene without multisampling and
reflections, for videos people and VLMs watch: about 3x cheaper in software rendering, a
mean pixel difference of about 2/255 from LIBERO's frame (edges and the table's reflection;
`benchmarks/render_cost.py` measures both).

Culling (fast quality only): a software renderer pays for every triangle it is given, seen or
not (a LIBERO scene: ~345k triangles, most of a frame's cost), and MuJoCo hands it every
visible-group geom. A "fast" frame skips the geoms whose bounding sphere lies wholly outside
the camera's view (about half of the triangles for the wrist camera). Without reflections and
shadow-casting lights such a geom cannot touch a pixel, so the frame is the same, pixel for
pixel (tests/sim/test_env.py, test_fast_frames_skip_geoms_outside_the_view_and_stay_pixel_identical);
with either, nothing is culled.
"""

from __future__ import annotations

import atexit
import weakref

import numpy as np

CAMERAS = ("agentview", "robot0_eye_in_hand")
QUALITIES = ("standard", "fast")
# 1: drew robosuite's collision geometry (geom group 0) over the visual meshes; 2: LIBERO's frame
RENDERER_VERSION = 2
LIBERO_GEOM_GROUPS = (0, 1, 1, 0, 0, 0)  # robosuite's offscreen vopt: collision hidden, visual shown
LIBERO_MAX_GEOM = 1000  # robosuite's MjvScene size: a scene past it drops geoms in LIBERO too
HIDDEN_GROUP = 5  # a group neither LIBERO nor we draw

# Every open renderer of this process, closed at exit. MuJoCo registers `eglTerminate` with
# atexit when it makes its first EGL context; a renderer still open after that (a worker's
# cached environment) is freed during interpreter teardown against a terminated display and
# prints `Exception ignored in ... GLContext.__del__` tracebacks into the stage's output.
# atexit runs last-registered first, so our hook, registered right after that first context,
# closes every renderer while the display is still alive.
_OPEN: weakref.WeakSet[FrameRenderer] = weakref.WeakSet()
_hook_registered = False


def close_all() -> None:
    """Close every renderer of this process (idempotent; runs at interpreter exit)."""
    for r in list(_OPEN):
        r.close()


def libero_scene_option():
    """The `MjvOption` robosuite's offscreen context renders LIBERO with (base.py sets the groups)."""
    import mujoco

    option = mujoco.MjvOption()
    option.geomgroup[:] = LIBERO_GEOM_GROUPS
    return option


class FrameRenderer:
    """Renders named cameras of one MuJoCo model at one resolution; reuse it across frames."""

    def __init__(self, model, size: int, quality: str = "standard", cull: bool = True):
        import mujoco

        if quality not in QUALITIES:
            raise ValueError(f"unknown render quality {quality!r}; choose from {QUALITIES}")
        self._mujoco = mujoco
        self.size = size
        self.fast = quality == "fast"
        self._model = model
        # a geom outside the view can still show in a reflection or cast a shadow into it
        self.cull = cull and self.fast and not np.any(model.light_castshadow)
        self._frustums: dict[str, tuple[int, float] | None] = {}
        # bounding spheres around geom_xpos, padded against rounding; 0 = unbounded (planes)
        self._rbound = np.asarray(model.geom_rbound) * 1.01 + 1e-3
        self._unbounded = np.asarray(model.geom_rbound) == 0
        samples = model.vis.quality.offsamples
        if self.fast:  # multisampling is fixed when the GL context is made
            model.vis.quality.offsamples = 0
        self.option = libero_scene_option()  # public: benchmarks set group 0 to redraw renderer v1
        try:
            self._renderer = mujoco.Renderer(model, height=size, width=size, max_geom=LIBERO_MAX_GEOM)
        finally:
            model.vis.quality.offsamples = samples
        global _hook_registered
        _OPEN.add(self)
        if not _hook_registered:  # after MuJoCo's own atexit hook, so that ours runs first
            atexit.register(close_all)
            _hook_registered = True

    def render(self, data, camera: str) -> np.ndarray:
        """HxWx3 uint8 image of `camera` for the current `data` (call mj_forward first)."""
        outside = self._outside(data, camera) if self.cull else None
        if outside is None or not outside.any():
            self._renderer.update_scene(data, camera=camera, scene_option=self.option)
        else:  # hide them for this scene update only (the model may be the physics' own)
            groups = self._model.geom_group
            saved = groups[outside]
            groups[outside] = HIDDEN_GROUP
            try:
                self._renderer.update_scene(data, camera=camera, scene_option=self.option)
            finally:
                groups[outside] = saved
        if self.fast:
            self._renderer.scene.flags[self._mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
        return self._renderer.render().copy()

    def _frustum(self, camera: str) -> tuple[int, float] | None:
        """(camera id, tan of half its vertical field of view); None when its view is not a
        plain perspective fovy (sensor-size intrinsics, orthographic): those are not culled."""
        if camera not in self._frustums:
            m = self._model
            c = self._mujoco.mj_name2id(m, self._mujoco.mjtObj.mjOBJ_CAMERA, camera)
            plain = c >= 0 and not np.any(m.cam_sensorsize[c]) and not getattr(m, "cam_orthographic", [0] * m.ncam)[c]
            self._frustums[camera] = (c, float(np.tan(np.deg2rad(m.cam_fovy[c]) / 2))) if plain else None
        return self._frustums[camera]

    def _outside(self, data, camera: str) -> np.ndarray | None:
        """Mask of geoms wholly outside `camera`'s view (square image: the same angle both ways)."""
        f = self._frustum(camera)
        if f is None:
            return None
        c, t = f
        rel = (data.geom_xpos - data.cam_xpos[c]) @ data.cam_xmat[c].reshape(3, 3)  # camera frame
        x, y, depth = np.abs(rel[:, 0]), np.abs(rel[:, 1]), -rel[:, 2]  # MuJoCo cameras look along -z
        reach = self._rbound * np.sqrt(1 + t * t)  # sphere radius against the tilted side planes
        out = (depth < -self._rbound) | (x - t * depth > reach) | (y - t * depth > reach)
        return out & ~self._unbounded

    def close(self) -> None:
        # closing explicitly avoids EGL tracebacks at interpreter exit
        if getattr(self, "_renderer", None) is not None:
            self._renderer.close()
            self._renderer = None
        _OPEN.discard(self)

    def __del__(self):  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
