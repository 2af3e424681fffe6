"""The simulation layer: the only package that imports LIBERO, robosuite or MuJoCo."""

import os

# MuJoCo picks its GL backend once, at `import mujoco`, and modules of this package import it
# at their top: the choice must be made before any of them loads. Headless machines need EGL
# (without it a fresh process that renders fails with "gladLoadGL error").
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

from pipeline.sim.env import ACTION_DIM, CONTROL_HZ, SimEnv, build_env  # noqa: E402
from pipeline.sim.pool import EnvCache  # noqa: E402
from pipeline.sim.registry import TaskSpec, all_tasks, get_task, tasks  # noqa: E402

__all__ = ["ACTION_DIM", "CONTROL_HZ", "EnvCache", "SimEnv", "TaskSpec", "all_tasks", "build_env", "get_task", "tasks"]
