"""Where the released scenes put the objects, against LIBERO's official init states.

Input: the release's scenes (`certify.SceneRef`: suite, task, BDDL, state file). Output:
`figures/object_positions.png` in the release, one panel per suite (LIBERO-100 beside its
halves): the x/y on the table of every movable object in the official init states of the
released tasks (LIBERO's init files, a grey 2-D histogram) and in the released scenes (red
points). A scene far from the grey mass is a layout the benchmark's own starts never show.

The positions are read from the states, not simulated: an object's free joint holds its
world position, at qpos address `a` = state index `1 + a` (the flattened state is time,
qpos, qvel). Finding the addresses needs the task's model, so each task model (task, BDDL)
is one unit of a `Stage` (`PositionsStage`) on the configured executor, its positions its
done marker's info (`<release>/_build/positions/_done/<unit>.done`), recorded with its
scenes' state hashes: a rebuild with the same scenes builds no environment.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline.atomic import write_with
from pipeline.config import SUITES, Config, reported_suites
from pipeline.release.certify import SceneRef
from pipeline.runner import Stage, UnitResult, WorkerContext

if TYPE_CHECKING:
    from rich.console import Console

    from pipeline.executors import Executor

FIGURE = "figures/object_positions.png"
POSITIONS_VERSION = 1  # bump when what a marker holds changes
_DIGITS = 4  # 0.1 mm: the markers' JSON stays small and its floats round-trip exactly


@dataclass(frozen=True)
class TaskModel:
    """One task model (task + BDDL) and the released scenes built on it."""

    suite: str
    task: str
    instruction: str
    bddl: Path
    bddl_sha: str
    scenes: tuple[SceneRef, ...]

    @property
    def unit_id(self) -> str:
        return f"{self.suite}__{self.task}__{self.bddl_sha[:12]}"


def task_models(scenes: list[SceneRef]) -> list[TaskModel]:
    groups: dict[tuple[str, str, str], list[SceneRef]] = {}
    for s in scenes:
        groups.setdefault((s.suite, s.task, s.cache_key.split("-")[0]), []).append(s)
    return [TaskModel(suite, task, refs[0].instruction, refs[0].bddl, sha, tuple(sorted(refs, key=lambda r: r.unit)))
            for (suite, task, sha), refs in sorted(groups.items())]


def object_xy(states: np.ndarray, addresses: list[int]) -> list[list[float]]:
    """x, y of each object (free-joint qpos address) in each flattened state, rounded."""
    states = np.atleast_2d(states)
    return [[round(float(s[1 + a]), _DIGITS), round(float(s[2 + a]), _DIGITS)] for s in states for a in addresses]


@dataclass
class PositionsStage(Stage[TaskModel]):
    cfg: Config
    models: list[TaskModel]
    folder: Path  # <release>/_build/positions
    name: str = "object positions"

    @property
    def root(self) -> Path:
        return self.folder

    def units(self, cfg: Config | None = None) -> list[TaskModel]:
        return self.models

    def fingerprint(self, model: TaskModel) -> dict:
        return {"scenes": [s.cache_key for s in model.scenes], "version": POSITIONS_VERSION}

    def process(self, model: TaskModel, ctx: WorkerContext) -> UnitResult:
        from pipeline.release.scene_physics import scene_task

        task = scene_task(model.suite, model.task, model.instruction, model.bddl)
        env = ctx.env(task)
        addresses = sorted(env.free_joints().values())
        scenes = np.stack([np.load(s.state, allow_pickle=False) for s in model.scenes])
        official, note, n_official = [], None, 0
        if task.index < 0:
            note = f"{model.suite}/{model.task}: not a LIBERO task, no official init states"
        else:
            init = np.asarray(task.init_states(), dtype=np.float64)
            if init.shape[1] != scenes.shape[1]:  # another model than the scenes': positions would be wrong
                note = f"{task.init_states_path}: states of length {init.shape[1]}, the scenes' are {scenes.shape[1]}"
            else:
                official, n_official = object_xy(init, addresses), len(init)
        info = {"suite": model.suite, "task": model.task, "n_scenes": len(scenes), "n_official": n_official,
                "scenes": object_xy(scenes, addresses), "official": official, "note": note}
        return UnitResult(info=info, ok=True, status="read")

    def set_aside(self, model: TaskModel, error: Exception) -> UnitResult:
        return UnitResult.set_aside(type(error).__name__, f"{model.bddl}: {error}")

    def results(self) -> list[dict]:
        from pipeline.runner.runner import finished

        done = finished(self, self.models)
        return [done[m.unit_id] for m in self.models if m.unit_id in done]


def collect(scenes: list[SceneRef], cfg: Config, folder: Path, executor: Executor | None = None,
            console: Console | None = None) -> list[dict]:
    """Each released task model's object positions (scenes and official init states)."""
    if not scenes:
        return []
    from pipeline.executors import make_executor
    from pipeline.runner import Runner

    stage = PositionsStage(cfg, task_models(scenes), folder)
    Runner(executor or make_executor(cfg.executor), console=console).run(stage, cfg)
    return stage.results()


def write_figure(results: list[dict], path: Path) -> None:
    """One panel per suite: official init states' object x/y as a grey 2-D histogram, the
    released scenes' as red points. Deterministic bytes for the same results."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    present = {r["suite"] for r in results}
    groups = reported_suites([s for s in SUITES if s in present] + sorted(present - set(SUITES))) or [("(none)", ())]
    cols = min(3, len(groups))
    rows = -(-len(groups) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.0 * rows), squeeze=False, dpi=100)
    for ax in axes.flat[len(groups):]:
        ax.set_visible(False)
    for ax, (name, members) in zip(axes.flat, groups):
        chosen = [r for r in results if r["suite"] in members]
        official = np.array([p for r in chosen for p in r["official"]]).reshape(-1, 2)
        scenes = np.array([p for r in chosen for p in r["scenes"]]).reshape(-1, 2)
        both = np.concatenate([official, scenes]) if len(official) + len(scenes) else np.zeros((1, 2))
        lo, hi = both.min(axis=0) - 0.05, both.max(axis=0) + 0.05
        if len(official):
            ax.hist2d(official[:, 0], official[:, 1], bins=40, range=[[lo[0], hi[0]], [lo[1], hi[1]]],
                      cmap="Greys", cmin=1)
        n_scenes, n_official = sum(r["n_scenes"] for r in chosen), sum(r["n_official"] for r in chosen)
        ax.scatter(scenes[:, 0], scenes[:, 1], s=14, c="tab:red", alpha=0.8, linewidths=0,
                   label=f"released scenes ({n_scenes})")
        ax.plot([], [], "s", color="0.4", label=f"official init states ({n_official})")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, loc="best")
    fig.suptitle("Object positions on the table: released scenes vs LIBERO's official init states", fontsize=10)
    fig.tight_layout()
    write_with(path, lambda p: fig.savefig(p, format="png", metadata={"Software": None}))
    plt.close(fig)
