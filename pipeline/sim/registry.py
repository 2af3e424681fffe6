"""The 130 LIBERO tasks: suite, name, instruction, BDDL file and official init states.

Read from LIBERO's benchmark definitions (task order 0), so the index of a task in its
suite is the same one LIBERO's own evaluation and published results use.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict

from pipeline.config import SUITES
from pipeline.sim.libero_setup import ensure_libero_ready


class TaskSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    suite: str
    index: int  # position in the suite, LIBERO task order 0
    name: str  # BDDL file stem
    instruction: str
    bddl_path: Path
    init_states_path: Path

    @property
    def task_id(self) -> str:
        return f"{self.suite}/{self.name}"

    def init_states(self) -> np.ndarray:
        return load_init_states(self.init_states_path)


@cache
def load_init_states(path: Path) -> np.ndarray:
    """The official init states of a task: (50, state_dim) float64 flattened MuJoCo states."""
    import torch  # LIBERO stores them as torch pickles

    arr = torch.load(path, weights_only=False)
    return np.asarray(arr, dtype=np.float64)


@cache
def all_tasks() -> tuple[TaskSpec, ...]:
    ensure_libero_ready()
    from libero.libero import get_libero_path
    from libero.libero.benchmark import get_benchmark_dict

    from pipeline.sim.env import _quiet

    bench = get_benchmark_dict()
    bddl_root = Path(get_libero_path("bddl_files"))
    init_root = Path(get_libero_path("init_states"))
    out = []
    for suite in SUITES:
        with _quiet():  # LIBERO prints its task order per suite
            b = bench[suite](task_order_index=0)
        for i in range(b.get_num_tasks()):
            t = b.get_task(i)
            out.append(
                TaskSpec(
                    suite=suite,
                    index=i,
                    name=t.name,
                    instruction=t.language,
                    bddl_path=bddl_root / t.problem_folder / t.bddl_file,
                    init_states_path=init_root / t.problem_folder / t.init_states_file,
                )
            )
    return tuple(out)


def tasks(suites: list[str] | None = None, names: list[str] | None = None) -> list[TaskSpec]:
    """Tasks filtered by suite and/or name (in registry order)."""
    chosen = [t for t in all_tasks() if suites is None or t.suite in suites]
    if names is not None:
        known = {t.name for t in chosen}
        missing = [n for n in names if n not in known]
        if missing:
            raise KeyError(f"unknown task name(s) in suites {suites}: {missing}")
        chosen = [t for t in chosen if t.name in names]
    return chosen


def get_task(suite: str, name: str) -> TaskSpec:
    for t in all_tasks():
        if t.suite == suite and t.name == name:
            return t
    raise KeyError(f"no task {suite}/{name}")
