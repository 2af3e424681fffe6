"""Reuse built environments: building one costs seconds, an episode start milliseconds.

Work that visits several episodes of a task (stage 1 rollouts, evidence replay, verify,
evaluation) should sort its units by task and go through an `EnvCache`, which keeps the
most recently used environments of a process alive and closes the rest.

Environments are keyed by task and by the *content* of the task's BDDL file: released
scenes carry their own (normalized) BDDL copy per episode folder, and scenes whose BDDL
text is the same share one environment, while a scene with different text gets its own.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict

from pipeline.sim.env import SimEnv
from pipeline.sim.registry import TaskSpec


def model_key(task: TaskSpec) -> tuple[str, str]:
    """What a built environment is for: the task and the content of its BDDL file."""
    return task.task_id, hashlib.sha256(task.bddl_path.read_bytes()).hexdigest()


class EnvCache:
    """Per-process LRU of built `SimEnv`s keyed by (task id, BDDL content). Not thread-safe."""

    def __init__(self, capacity: int = 1):
        if capacity < 1:
            raise ValueError("capacity must be >= 1")
        self.capacity = capacity
        self._envs: OrderedDict[tuple[str, str], SimEnv] = OrderedDict()
        self.builds = 0  # how many environments were built (for tests and progress)

    def get(self, task: TaskSpec) -> SimEnv:
        key = model_key(task)
        env = self._envs.pop(key, None)
        if env is None:
            while len(self._envs) >= self.capacity:
                _, old = self._envs.popitem(last=False)
                old.close()
            env = SimEnv(task)
            self.builds += 1
        self._envs[key] = env
        return env

    def close(self) -> None:
        while self._envs:
            _, env = self._envs.popitem()
            env.close()

    def __enter__(self) -> EnvCache:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
