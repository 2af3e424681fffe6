"""Recovery scene snapshots in the release layout.

Input: a task (its BDDL), an episode id, the onset step and the flattened MuJoCo state at
that step, plus the built environment of the task for the checks. Output, under the
stage-2 folder:
    selected_bddl_scenes_<suite>/<task_name>/episode_<episode_id>/step_<NNNN>.bddl
    selected_bddl_scenes_<suite>/<task_name>/episode_<episode_id>/step_<NNNN>_sim_state.npy
(NNNN = the step, zero-padded to 4 digits). The BDDL is the task's own file normalized to one
declaration line per type (bddl_normalize); the npy is a float64 vector of the env's
state_dim, what LIBERO's `set_init_state` (and `SimEnv.reset_to`) accepts.

Checks before anything is written (each failure raises EpisodeError with a reason the
runner quarantines): the normalized BDDL parses with LIBERO's parser and declares the
objects of the built environment in the same order (so the state layout matches); the
state has the env's length; the goal is NOT satisfied in that state (`goal_satisfied_at_onset`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.atomic import write_text, write_with
from pipeline.errors import EpisodeError
from pipeline.layout import episode_key, scene_files
from pipeline.sim.env import parse_bddl
from pipeline.stage2.bddl_normalize import normalize_bddl


def _declared_objects(parsed: dict) -> list[str]:
    return [name for names in parsed["objects"].values() for name in names]


def check_scene(env, bddl_text: str, state: np.ndarray, scratch: Path) -> None:
    """Raise EpisodeError if the scene would not restore as the same, unfinished task."""
    write_text(scratch, bddl_text)
    try:
        parsed = parse_bddl(scratch)
    except ValueError as e:
        raise EpisodeError("bddl_unparsable", str(e)) from None
    finally:
        scratch.unlink(missing_ok=True)
    if _declared_objects(parsed) != env.object_names:
        raise EpisodeError("bddl_objects_mismatch",
                           f"normalized BDDL declares {_declared_objects(parsed)}, env has {env.object_names}")
    if state.shape != (env.state_dim,):
        raise EpisodeError("state_shape", f"state has shape {state.shape}, env needs ({env.state_dim},)")
    env.set_state(state)
    if env.goal_satisfied():
        raise EpisodeError("goal_satisfied_at_onset", "the task's goal already holds in the onset state")


def write_scene(stage2: Path, env, suite: str, task: str, episode_id: str, step: int,
                state: np.ndarray) -> tuple[Path, Path]:
    """Check and write the BDDL + npy pair; return their paths."""
    files = scene_files(stage2, episode_key(suite, task, episode_id), step)
    bddl = normalize_bddl(Path(env.task.bddl_path).read_text())
    state = np.asarray(state, dtype=np.float64)
    check_scene(env, bddl, state, files.check_scratch)
    npy_path, bddl_path = files.state, files.bddl
    write_with(npy_path, lambda p: np.save(p, state))
    write_text(bddl_path, bddl)
    return bddl_path, npy_path
