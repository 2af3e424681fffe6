"""`policy.kind: lerobot` against LeRobot itself (lerobot 0.4.4 in `.venv-lerobot`).

1. The observation we send equals, array for array, what LeRobot's own LIBERO env code
   (`lerobot/envs/libero.py:_format_raw_obs`) builds from LIBERO's observation of the same
   simulator state, and the LeRobot export's frames and state equal what LeRobot's LIBERO
   processing then hands a policy (so a policy trained on the export sees the same at run time).
2. The loop in miniature: `lerobot-train` trains a tiny ACT a few steps on an exported smoke
   dataset; LeRobot's PolicyServer serves the checkpoint as a stage-1 failure generator (one
   episode) and in `recover eval` beside the scripted expert (one trial each, one report).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.config import Config
from pipeline.policies.lerobot_policy import CAMERAS, libero_observation
from pipeline.rollout import observe
from pipeline.sim import SimEnv
from tests.release.factories import SUITE, make_run, npy_bytes, release_config, scene_source  # noqa: F401

pytestmark = pytest.mark.sim

REPO = Path(__file__).resolve().parents[2]
LEROBOT_PYTHON = Path(os.environ.get("LEROBOT_PYTHON", REPO / ".venv-lerobot/bin/python"))
SIZE = 64


def need_lerobot() -> None:
    if not LEROBOT_PYTHON.is_file():
        pytest.fail(f"LeRobot environment missing ({LEROBOT_PYTHON}); build it with `make setup-test` "
                    "(or `bash scripts/setup_lerobot.sh`)")


class Cameras:  # what rollout.observe asks of an image policy
    cameras, image_size = CAMERAS, SIZE


def test_observation_equals_what_lerobots_libero_env_builds(tmp_path):
    from libero.libero.envs import OffScreenRenderEnv

    from pipeline.release.lerobot_export import render_episode
    from pipeline.sim import tasks
    from pipeline.sim.restore import restore

    need_lerobot()
    task = tasks([SUITE])[0]
    # mid-episode: the arm moved down and forward, the gripper closing
    actions = [np.array([0.3, 0.1, -0.4, 0.0, 0.0, 0.2, 1.0 if t > 15 else -1.0]) for t in range(30)]
    with SimEnv(task) as env:
        env.reset_to(task.init_states()[0])
        for a in actions:
            env.step(a)
        state = env.get_state()
        ours = libero_observation(observe(env, Cameras(), len(actions)))
        # what the LeRobot export writes for this state (it sets each logged state, then draws)
        robot, frames = render_episode(env, state[None], SIZE)
        export_frames = {k: v[0] for k, v in frames.items()}
        export_state = robot[0].astype(np.float32)
        # after a step MuJoCo's body poses are those before the last substep's integration (what
        # LIBERO draws then too); a set state has its own: the export's frames are of the latter
        export_obs = libero_observation(observe(env, Cameras(), 0))
    # LIBERO's own environment: the same restore (plain LIBERO plus restore's three lines), then
    # robosuite's own env.step: the same states bit for bit (pipeline/sim/restore.py)
    lib = OffScreenRenderEnv(bddl_file_name=str(task.bddl_path), camera_heights=SIZE, camera_widths=SIZE)
    try:
        restore(lib, task.init_states()[0])
        for a in actions:
            lib.step(a)
        assert np.array_equal(lib.get_sim_state(), state)
        # robosuite's observation of this state: its observables are sampled on their own clock
        # (20 Hz from the 500 Hz substeps), so the one `step` returned lags it by a few substeps
        raw = lib.env._get_observations(force_update=True)
        mat = np.array(lib.env.robots[0].controller.ee_ori_mat)
    finally:
        lib.close()
    keys = ["agentview_image", "robot0_eye_in_hand_image", "robot0_eef_pos", "robot0_eef_quat",
            "robot0_gripper_qpos", "robot0_gripper_qvel", "robot0_joint_pos", "robot0_joint_vel"]
    np.savez(tmp_path / "in.npz", **{k: raw[k] for k in keys}, ee_ori_mat=mat, task=np.array(task.instruction),
             **{f"ours/{k}": v for k, v in ours.items()}, **{f"export/{k}": v for k, v in export_obs.items()})
    res = subprocess.run([str(LEROBOT_PYTHON), str(Path(__file__).with_name("lerobot_libero_obs.py")),
                          str(tmp_path / "in.npz"), str(tmp_path / "out.npz")], capture_output=True, text=True,
                         timeout=300, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert res.returncode == 0, res.stderr[-4000:]
    with np.load(tmp_path / "out.npz") as z:
        out = {k: z[k] for k in z.files}
    theirs = {k[len("theirs/"):]: v for k, v in out.items() if k.startswith("theirs/")}
    assert sorted(theirs) == sorted(ours)
    for k, want in theirs.items():
        assert ours[k].dtype == want.dtype and ours[k].shape == want.shape, k
        assert np.array_equal(ours[k], want), f"{k} differs from LeRobot's LIBERO observation"
    # what the bridge then hands the PolicyServer: the same for theirs and ours
    policy = {k[len("policy/"):]: v for k, v in out.items() if k.startswith("policy/")}
    for k, v in policy.items():
        assert np.array_equal(out[f"ours_policy/{k}"], v), k
    assert str(policy["task"]) == task.instruction
    # the export shows a policy what LeRobot's LIBERO processing shows it (turned 180 degrees)
    served = {k[len("export_policy/"):]: v for k, v in out.items() if k.startswith("export_policy/")}
    assert np.array_equal(export_frames["observation.images.image"], served["image"])
    assert np.array_equal(export_frames["observation.images.image2"], served["image2"])
    names = ["eef_x", "eef_y", "eef_z", "axis_angle1", "axis_angle2", "axis_angle3", "gripper_left", "gripper_right"]
    state8 = np.array([float(served[n]) for n in names], dtype=np.float32)
    assert np.allclose(export_state, state8, atol=1e-6), (export_state, state8)  # LeRobot's float32 arithmetic


@pytest.fixture(scope="module")
def trained(tmp_path_factory, scene_source):
    """A tiny ACT trained 4 steps by `lerobot-train` on a 2-episode exported rollouts dataset."""
    from pipeline.policies.lerobot_train import tiny_act_args, train
    from pipeline.release.build import build
    from pipeline.release.lerobot_export import run as export

    need_lerobot()
    root = tmp_path_factory.mktemp("lerobot")
    good = npy_bytes(scene_source.failure)
    run = make_run(root / "run", scene_source, {"ep-a": (good, scene_source.bddl_text),
                                                "ep-b": (good, scene_source.bddl_text)})
    cfg = release_config(run, executor="inline", lerobot_image_size=SIZE)
    build(cfg)
    out = export(cfg, only=["rollouts"])
    result = train(out / "rollouts", root / "act", steps=4, batch_size=4, policy_args=tiny_act_args(chunk_size=8),
                   log_freq=1)
    return run, result


def lerobot_policy(path: Path, name: str = "act-tiny") -> dict:
    return {"kind": "lerobot", "name": name, "lerobot": {"path": str(path), "image_size": SIZE}}


def test_a_policy_trained_on_the_export_generates_failures_and_is_evaluated(trained, tmp_path):
    from pipeline.eval.records import read_rows
    from pipeline.eval.run import run as run_eval
    from pipeline.records import read_episodes
    from pipeline.stage1.run import run as run_stage1

    run, result = trained
    assert [s for s, _ in result.losses] == [1, 2, 3, 4]  # lerobot-train logged every step
    assert all(np.isfinite(loss) and loss > 0 for _, loss in result.losses)
    ckpt = result.checkpoint
    assert (ckpt / "config.json").is_file() and (ckpt / "model.safetensors").is_file()
    # stage 1 with the checkpoint as failure generator: one episode on the real simulator
    tasks = {"suites": [SUITE], "max_tasks_per_suite": 1, "init_states": [0]}
    gen = Config.model_validate({
        "run": {"output_dir": str(tmp_path / "gen")}, "executor": {"kind": "inline"}, "tasks": tasks,
        "stage1": {"policy": lerobot_policy(ckpt), "rollout": {"horizon": 16, "chunk_size": 8},
                   "video": {"render": "none"}}})
    summary = run_stage1(gen)
    assert (summary["done"], summary["errors"]) == (1, [])
    (ep,) = read_episodes(tmp_path / "gen/stage1/episodes.parquet")
    assert (ep.policy, ep.policy_kind, ep.steps) == ("act-tiny", "lerobot", 16)
    assert ep.policy_params["policy_type"] == "act" and ep.policy_params["chunk_size"] == 8
    actions = np.load(tmp_path / "gen/stage1" / ep.path / "actions.npy")
    assert actions.shape == (16, 7) and np.abs(actions).max() <= 1.0 and np.abs(actions).max() > 0
    # recover eval: the scripted expert and the checkpoint side by side, one trial each
    ev = Config.model_validate({
        "run": {"output_dir": str(run)}, "executor": {"kind": "inline"}, "tasks": tasks,
        "release": {"certify_tries": 0},
        "eval": {"policies": [{"kind": "scripted", "name": "expert"}, lerobot_policy(ckpt)],
                 "trials_per_condition": 1, "gripper_conditions": ["open"], "horizon": 16, "rd": False,
                 "official_trials": 0, "max_scenes": 1, "split": "all"}})
    out = run_eval(ev)
    rows = read_rows(out / "episodes.parquet")
    assert sorted((r.policy, r.policy_kind) for r in rows) == [("act-tiny", "lerobot"), ("expert", "scripted")]
    table = pq.read_table(out / "episodes.parquet").to_pylist()
    assert all(len(r["actions"]) == r["steps"] for r in table)
    report = (out / "report.md").read_text()
    assert "act-tiny" in report and "expert" in report
