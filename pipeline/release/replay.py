"""Replay recorded episodes in plain LIBERO: the recorded actions, stepped by robosuite's
own `env.step` (never the project's fast step) from the one restore, must give the recorded
states bit for bit.

Inputs: a built `SimEnv` (its `libero` is LIBERO's `ControlEnv`), an episode folder
(`actions.npy` float64 as stepped, `states.npy`) and where the episode started:
- a recovery demo: its scene's state, restored with `hold_grasp` (as `recover demos` did);
  LIBERO's goal check must first hold after the last action (demos stop on success);
- a stage-1 rollout (and its pre-failure history, a prefix): its LIBERO init state, then
  `settle_steps` zero-arm, gripper-open actions (stage 1's settle), then the actions.
Outputs: a `Replay` (first differing state row, first goal step) and problem strings that
name the file: `recover demos` drops a demo that does not replay, the LeRobot export sets
aside a rollout that does not, `recover verify --replay` (`verify_demos`) reports both.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console

from pipeline.layout import EpisodeFiles, RecoveriesLayout, RunLayout
from pipeline.sim import ACTION_DIM, SimEnv

SETTLE_ACTION = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0])  # `SimEnv.settle`'s


@dataclass(frozen=True)
class Replay:
    steps: int
    first_mismatch: int | None  # first state row that differs from the recording; None: none does
    goal_step: int | None  # first step after which LIBERO's goal check holds

    @property
    def identical(self) -> bool:
        return self.first_mismatch is None


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def replay(env: SimEnv, start: np.ndarray, actions: np.ndarray, states: np.ndarray, *,
           hold_grasp: bool, settle_steps: int = 0) -> Replay:
    """Restore `start` (the one restore), settle, step `actions` with LIBERO's `env.step` and
    compare every state with `states` (row t: before action t)."""
    env.reset_to(start, hold_grasp=hold_grasp)
    lib = env.libero
    for _ in range(settle_steps):
        lib.step(SETTLE_ACTION.copy())
    first = None if _same_bits(lib.get_sim_state(), states[0]) else 0
    goal = None
    for t, a in enumerate(actions):
        lib.step(np.array(a, dtype=np.float64))
        if first is None and not _same_bits(lib.get_sim_state(), states[t + 1]):
            first = t + 1
        if goal is None and lib.check_success():
            goal = t + 1
    return Replay(len(actions), first, goal)


class ReplayInputError(ValueError):
    """An episode's recorded files cannot be replayed (missing, unreadable, wrong shape)."""


def load_episode(folder: Path, length: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(actions float64 (n, 7), states (n+1, dim)) of an episode folder, the first `length`
    steps; ReplayInputError naming the file and what is wrong."""
    files = EpisodeFiles(Path(folder))
    try:
        actions = np.load(files.actions, allow_pickle=False)
    except FileNotFoundError:
        raise ReplayInputError(f"{files.actions}: missing (episodes recorded before actions were stored at full "
                               "precision cannot replay bit for bit; record them again)") from None
    except (OSError, ValueError) as e:
        raise ReplayInputError(f"{files.actions}: not a readable .npy: {e}") from None
    try:
        states = np.load(files.states, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise ReplayInputError(f"{files.states}: not a readable .npy: {e}") from None
    if actions.dtype != np.float64 or actions.ndim != 2 or actions.shape[1] != ACTION_DIM:
        raise ReplayInputError(f"{files.actions}: need (steps, {ACTION_DIM}) float64, got {actions.shape} {actions.dtype}")
    if states.ndim != 2 or len(states) != len(actions) + 1:
        raise ReplayInputError(f"{files.states}: {states.shape} states for {len(actions)} actions in {files.actions} "
                               f"(need one more state than actions)")
    if not np.isfinite(actions).all():
        raise ReplayInputError(f"{files.actions}: non-finite action at step {int(np.argmin(np.isfinite(actions).all(1)))}")
    n = len(actions) if length is None else length
    if n > len(actions):
        raise ReplayInputError(f"{files.actions}: {len(actions)} actions, but {n} are to be replayed")
    return actions[:n], states[: n + 1]


def replay_problems(r: Replay, folder: Path, goal_at: int | None = None) -> list[str]:
    """What is wrong with a replay: a state that differs, or (demos) the goal not first reached
    at the recorded step `goal_at`."""
    files = EpisodeFiles(Path(folder))
    out = []
    if r.first_mismatch is not None:
        out.append(f"{files.actions}: replayed in plain LIBERO, the state after step {r.first_mismatch} differs "
                   f"from {files.states.name} row {r.first_mismatch} (the actions are not the ones executed)"
                   if r.first_mismatch else f"{files.states}: row 0 is not the restored start state")
    if goal_at is not None and r.goal_step != goal_at:
        out.append(f"{files.actions}: replayed in plain LIBERO, the goal first holds "
                   f"{'never' if r.goal_step is None else f'after step {r.goal_step}'}, recorded after step {goal_at}")
    return out


def check_demo(env: SimEnv, scene_state: np.ndarray, folder: Path, steps: int) -> tuple[Replay | None, list[str]]:
    """Replay one recovery demo from its scene; (its replay, problems naming its files)."""
    try:
        actions, states = load_episode(folder)
    except ReplayInputError as e:
        return None, [str(e)]
    if len(actions) != steps:
        return None, [f"{EpisodeFiles(Path(folder)).actions}: {len(actions)} actions, the demo record says {steps}"]
    r = replay(env, scene_state, actions, states, hold_grasp=True)
    return r, replay_problems(r, folder, goal_at=steps)


def check_rollout(env: SimEnv, init_state: np.ndarray, settle_steps: int, folder: Path,
                  length: int | None = None) -> list[str]:
    """Replay a stage-1 episode's first `length` steps from its init state; problems."""
    actions, states = load_episode(folder, length)
    return replay_problems(replay(env, init_state, actions, states, hold_grasp=False, settle_steps=settle_steps),
                           folder)


@dataclass(frozen=True)
class ReplayStart:
    """Where a recorded episode began: a LIBERO init state of its task, then stage 1's
    settle (a rollout), or a released scene's state file (a recovery demo)."""

    init_state: int | None = None
    settle_steps: int = 0
    scene_state: Path | None = None


def check_exported(env: SimEnv, start: ReplayStart, folder: Path, length: int) -> list[str]:
    """The LeRobot export's check of one episode (its first `length` steps); problems."""
    if start.scene_state is not None:
        state = np.load(start.scene_state, allow_pickle=False)
        actions, states = load_episode(folder, length)
        return replay_problems(replay(env, state, actions, states, hold_grasp=True), folder)
    return check_rollout(env, env.task.init_states()[start.init_state], start.settle_steps, folder, length)


# ---- `recover verify --replay`: every recovery demo of a release ---------------------------------

@dataclass
class DemoReplayReport:
    recorded: int = 0  # demos listed in demos.parquet
    replayed: int = 0  # ... whose files loaded and whose scene restored
    identical: int = 0  # ... bit-identical states at every step
    goal_at_step: int = 0  # ... whose goal first held at the recorded step
    dropped: int = 0  # demos `recover demos` dropped for not replaying (scenes.jsonl)
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems and self.identical == self.goal_at_step == self.recorded

    def line(self) -> str:
        return (f"demos recorded {self.recorded}, replayed {self.replayed}, bit-identical at every step "
                f"{self.identical}, goal reached at the recorded step {self.goal_at_step}, dropped for not "
                f"replaying {self.dropped}")


def dropped_count(recoveries: Path) -> int:
    log = RecoveriesLayout(recoveries).scenes_log
    if not log.is_file():
        return 0
    return sum(json.loads(line).get("unreplayable", 0) for line in log.read_text().splitlines() if line.strip())


def verify_demos(release: Path, recoveries: Path) -> DemoReplayReport:
    """Replay every demo of `recoveries/demos.parquet` from its scene in `release`."""
    from pipeline.release.manifest import MANIFEST_NAME, read_manifest
    from pipeline.release.recovery_demos import read_demos, scene_id
    from pipeline.release.scene_physics import scene_task

    rep = DemoReplayReport()
    table = RecoveriesLayout(recoveries).demos
    try:
        demos = read_demos(table)
        rows = {scene_id(r): r for r in read_manifest(release / MANIFEST_NAME)}
    except (FileNotFoundError, ValueError) as e:
        rep.problems.append(str(e) if not isinstance(e, FileNotFoundError) else f"{e.filename}: missing")
        return rep
    rep.recorded, rep.dropped = len(demos), dropped_count(recoveries)
    todo = []
    for d in demos:
        row = rows.get(d.scene_id)
        if row is None:
            rep.problems.append(f"{table}: demo {d.scene_id}/demo_{d.demo_index} names a scene not in the release")
        else:
            todo.append((row, d))
    todo.sort(key=lambda x: (x[0].suite, x[0].task, x[0].bddl_sha256, x[1].scene_id, x[1].demo_index))
    env, model = None, None
    try:
        for row, d in todo:
            if (row.suite, row.task, row.bddl_sha256) != model:
                if env is not None:
                    env.close()
                env = SimEnv(scene_task(row.suite, row.task, row.instruction, release / row.bddl_path))
                model = (row.suite, row.task, row.bddl_sha256)
            state = np.load(release / row.state_path, allow_pickle=False)
            r, problems = check_demo(env, state, recoveries / d.path, d.steps)
            rep.problems += problems
            if r is not None:
                rep.replayed += 1
                rep.identical += r.identical
                rep.goal_at_step += r.goal_step == d.steps
    finally:
        if env is not None:
            env.close()
    return rep


def main_demos(release: Path, recoveries: Path | None, console: Console) -> int:
    """`recover verify --replay`'s part: print the counts and every problem; 1 if any."""
    # a release made by `recover release` sits in its run folder, beside the demos
    recoveries = Path(recoveries) if recoveries else RunLayout(Path(release).parent).recoveries.root
    rep = verify_demos(Path(release), recoveries)
    for p in rep.problems:
        console.print(f"[red]problem[/red] {p}", highlight=False, soft_wrap=True)
    colour = "green" if rep.ok else "red"
    console.print(f"[{colour}]replay ({recoveries}): {rep.line()}[/{colour}]", highlight=False, soft_wrap=True)
    return 0 if rep.ok else 1

