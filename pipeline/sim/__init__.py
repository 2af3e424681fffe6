"""The simulation layer: the only package that imports LIBERO, robosuite or MuJoCo."""

from pipeline.sim.env import ACTION_DIM, CONTROL_HZ, SimEnv, build_env
from pipeline.sim.pool import EnvCache
from pipeline.sim.registry import TaskSpec, all_tasks, get_task, tasks

__all__ = ["ACTION_DIM", "CONTROL_HZ", "EnvCache", "SimEnv", "TaskSpec", "all_tasks", "build_env", "get_task", "tasks"]
