"""Recorded episodes replay in plain LIBERO: from the dataset card's restore, the stored actions
stepped by robosuite's own `env.step` give the recorded states bit for bit, and one stored
action moved by one float32 ulp does not. Plain LIBERO imports without asking anything."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from pipeline.config import Config
from pipeline.release.card import restore_section
from pipeline.release.replay import check_rollout, load_episode, replay
from pipeline.release.scene_physics import restore_scene
from pipeline.rollout import StepInfo
from pipeline.stage1.recorder import EpisodeRecorder

# float64 commands a float32 column cannot hold exactly (as the scripted experts send)
ACTIONS = [np.array([0.31415926535, -0.2718281828, 0.1414213562, 0.05, -0.03, 0.0, -1.0])] * 6 + \
          [np.array([-0.1732050807, 0.2236067977, -0.4142135623, 0.0, 0.0, 0.02, 1.0])] * 10


def card_restore():
    """`restore` exactly as the dataset card prints it (its code block, run as a user would)."""
    block = re.search(r"```python\n(.*?)```", restore_section(), re.S).group(1)
    scope: dict = {}
    exec(block.split("\nenv = ")[0], scope)  # the imports and the function; not the example call
    return scope["restore"]


def one_ulp(actions: np.ndarray, step: int) -> np.ndarray:
    """The actions with one value of `step` moved by one float32 ulp."""
    out = actions.copy()
    out[step, 0] = np.nextafter(np.float32(out[step, 0]), np.float32(np.inf))
    return out


def scene_start(folder):
    return np.load(folder / "states.npy")[0]  # the restored scene: row 0 of the recording


@pytest.fixture(scope="module")
def env(scene_source):
    from pipeline.sim import SimEnv

    e = SimEnv(scene_source.task)
    yield e
    e.close()


@pytest.fixture(scope="module")
def demo(env, scene_source, tmp_path_factory):
    """A short rollout from a released scene, recorded as `recover demos` records one."""
    restore_scene(env, scene_source.failure)
    rec = EpisodeRecorder(env)
    for t, a in enumerate(ACTIONS):
        rec.on_step(StepInfo(step=t, action=a, query=t == 0, goal=env.step(a)))
    folder = tmp_path_factory.mktemp("demo")
    rec.write(folder)
    return folder


@pytest.mark.sim
def test_a_scene_rollout_replays_bit_for_bit_from_the_card_in_a_fresh_plain_libero_env(demo, scene_source):
    from libero.libero.envs.env_wrapper import ControlEnv

    actions, states = load_episode(demo)
    assert actions.dtype == np.float64 and np.array_equal(actions, np.array(ACTIONS))
    restore = card_restore()
    lib = ControlEnv(bddl_file_name=str(scene_source.task.bddl_path), has_renderer=False,
                     has_offscreen_renderer=False, use_camera_obs=False)  # LIBERO's defaults otherwise
    try:
        def run(acts: np.ndarray) -> list[int]:
            restore(lib, scene_source.failure, hold_grasp=True)
            differ = [0] if lib.get_sim_state().tobytes() != states[0].tobytes() else []
            for t, a in enumerate(acts):
                lib.step(a)
                if lib.get_sim_state().tobytes() != states[t + 1].tobytes():
                    differ.append(t + 1)
            return differ

        assert run(actions) == []  # every state, every bit
        assert run(one_ulp(actions, 3))[0] == 4  # one float32 ulp of one action: the next state differs
        # the float32 column (steps.parquet, LeRobot) is not what ran: it does not replay exactly
        assert run(actions.astype(np.float32).astype(np.float64)) != []
    finally:
        lib.close()


@pytest.mark.sim
def test_replay_names_the_action_file_a_one_ulp_change_corrupts(env, demo):
    from pipeline.release.replay import check_demo, replay_problems

    actions, states = load_episode(demo)
    good, problems = check_demo(env, scene_start(demo), demo, len(actions))
    assert good.identical  # the project's reused environment (soft reset) replays it too
    assert problems == [f"{demo / 'actions.npy'}: replayed in plain LIBERO, the goal first holds never, "
                        f"recorded after step {len(actions)}"]  # this rollout never reaches the goal
    bad = replay(env, scene_start(demo), one_ulp(actions, 5), states, hold_grasp=True)
    assert bad.first_mismatch == 6
    assert replay_problems(bad, demo)[0].startswith(f"{demo / 'actions.npy'}: replayed in plain LIBERO, the state "
                                                    "after step 6 differs")


@pytest.mark.sim
def test_a_stage1_rollout_replays_bit_for_bit_from_its_init_state(env, tmp_path):
    from pipeline.policies.scripted import make_scripted_policy
    from pipeline.stage1.units import plan_units
    from pipeline.stage1.worker import run_one

    cfg = Config.model_validate({
        "run": {"output_dir": str(tmp_path), "seed": 3},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": [1]},
        "stage1": {"policy": {"kind": "scripted", "scripted": {"noise": {"action_noise": 0.2}}},
                   "rollout": {"horizon": 30, "chunk_size": 8, "settle_steps": 10},
                   "video": {"render": "none"}},
    })
    (unit,) = plan_units(cfg)
    policy = make_scripted_policy(cfg.stage1.policy.scripted)
    rec = run_one(env, policy, unit, cfg, tmp_path / "stage1")
    folder = tmp_path / "stage1" / rec.path
    actions, _ = load_episode(folder)
    assert len(actions) == rec.steps == 30
    init = env.task.init_states()[rec.init_state]
    assert check_rollout(env, init, rec.settle_steps, folder) == []
    np.save(folder / "actions.npy", one_ulp(actions, 0))
    (problem,) = check_rollout(env, init, rec.settle_steps, folder)
    assert problem.startswith(f"{folder / 'actions.npy'}: replayed in plain LIBERO, the state after step 1 differs")


def test_plain_libero_imports_without_asking_for_a_folder(tmp_path):
    """A fresh process, a clean environment (no LIBERO_CONFIG_PATH, an empty home), stdin closed."""
    from pipeline.sim.libero_setup import ensure_libero_ready

    ensure_libero_ready()  # what `make setup` runs
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", "import libero.libero"], env=env, stdin=subprocess.DEVNULL,
                         capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "input" not in out.stderr and not (tmp_path / ".libero").exists()
