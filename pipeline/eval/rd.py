"""Start states for recovery degradation (RD): every `every` steps along a failed rollout.

Inputs: a stage-1 episode folder (`states.npy`, (steps+1, state_dim), row t = the state
before action t; `steps.parquet`, the step log with the actions) and the failure-onset
step of the scene cut from it.
Output: `RDStart`s at t = 0, every, 2*every, ... (<= the last row), each labelled with the
phase of stage 2's split it lies in (`pre`, `during` or `post`: `stage2.phases`, the
episode's Localization), or, where stage 2's phases are not at hand, `pre` (t < onset) or
`post` (t >= onset); each with the gripper command that was in force at t
(the sign of action t-1's gripper; open at t = 0): the rerun initializes the gripper to it,
because the command ramp is not in the saved state (see `pipeline.sim.env`).

Invariant: pure given the files; the same rollout and onset always give the same starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.layout import EpisodeFiles, Stage1Layout, Stage2Layout, episode_key
from pipeline.records import PhaseFields


@dataclass(frozen=True)
class RDStart:
    start_step: int
    phase: str  # pre | during | post
    gripper: str  # open | closed


def phase_at(t: int, onset: int, phases: PhaseFields | None) -> str:
    """The phase of state row t: stage 2's half-open ranges, else pre / post at the onset."""
    if phases is None:
        return "pre" if t < onset else "post"
    for name in ("pre", "during", "post"):
        start, end = getattr(phases, name)
        if start <= t < end:
            return name
    return "post"  # rows past stage 2's last range (a longer log than it saw): after the failure


def start_steps(n_states: int, onset: int, every: int, phases: PhaseFields | None = None) -> list[tuple[int, str]]:
    """(step, phase) of the RD start states of a rollout with `n_states` saved states."""
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    if not 0 <= onset < n_states:
        raise ValueError(f"onset step {onset} is outside the rollout's states [0, {n_states})")
    return [(t, phase_at(t, onset, phases)) for t in range(0, n_states, every)]


def at_onset(phases: PhaseFields, onset: int, n_states: int) -> PhaseFields:
    """Stage 2's phases moved to the scene's reviewed onset (reviewers may move it): pre ends
    there, during keeps stage 2's end (at least one step), post is the rest."""
    if phases.during[0] == onset:
        return phases
    end = min(max(phases.during[1], onset + 1), n_states)
    return PhaseFields(pre=(0, onset), during=(onset, end), post=(end, max(end, n_states)))


def stage2_phases(stage2_dir: str | Path, key: str) -> PhaseFields | None:
    """Stage 2's phases of a source episode (its Localization), or None where there is none."""
    from pydantic import ValidationError

    from pipeline.records import Localization

    path = Stage2Layout(Path(stage2_dir)).localization_of_key(key)
    if not path.is_file():
        return None
    try:
        return Localization.model_validate_json(path.read_text()).phases
    except (ValueError, ValidationError) as e:
        raise ValueError(f"{path}: not a Localization: {e}") from None


def gripper_commands(actions: np.ndarray) -> list[str]:
    """Gripper command in force before each step t (len(actions) + 1 entries)."""
    out = ["open"]
    for a in actions:
        out.append("closed" if a[6] > 0 else "open")
    return out


def episode_dir(stage1_dir: str | Path, suite: str, task: str, episode_id: str) -> Path:
    return Stage1Layout(Path(stage1_dir)).episode_dir(episode_key(suite, task, episode_id))


def rd_starts(folder: str | Path, onset: int, every: int, phases: PhaseFields | None = None) -> list[RDStart]:
    """RD start states of one stage-1 episode folder; FileNotFoundError names what is missing.
    `onset`: the failure onset (the reviewed one for a released scene), where stage 2's
    `phases` are moved to; without them, the pre / post boundary."""
    import pyarrow.parquet as pq

    folder = Path(folder)
    states_path, steps_path = EpisodeFiles(folder).states, EpisodeFiles(folder).steps
    for p in (states_path, steps_path):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: missing (needed for RD reruns)")
    n_states = np.load(states_path, mmap_mode="r").shape[0]
    actions = np.asarray(pq.read_table(steps_path, columns=["action"]).column("action").to_pylist(), dtype=np.float64)
    if len(actions) != n_states - 1:
        raise ValueError(f"{folder}: {n_states} states but {len(actions)} logged actions (need states = actions + 1)")
    grip = gripper_commands(actions.reshape(-1, 7))
    if phases is not None:
        phases = at_onset(phases, onset, n_states)
    return [RDStart(t, phase, grip[t]) for t, phase in start_steps(n_states, onset, every, phases)]


def load_start_state(folder: str | Path, step: int) -> np.ndarray:
    return np.array(np.load(EpisodeFiles(Path(folder)).states, mmap_mode="r")[step], dtype=np.float64)
