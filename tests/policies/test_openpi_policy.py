"""The openpi client against a real `openpi-server` on loopback, driving real LIBERO."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from pipeline.config import OpenpiPolicyConfig, load_config
from pipeline.errors import FatalError
from pipeline.policies.openpi_policy import OpenpiPolicy, libero_state, prepare_image, quat_xyzw_to_axis_angle
from pipeline.records import read_episodes
from pipeline.rollout import observe, run_episode

from openpi_state_server import TARGET, digest  # noqa: E402  (beside this file)

SERVER = Path(__file__).with_name("openpi_state_server.py")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    port = _free_port()
    log = tmp_path_factory.mktemp("openpi") / "requests.jsonl"
    proc = subprocess.Popen([sys.executable, str(SERVER), "--port", str(port), "--log", str(log)])
    try:
        for _ in range(100):
            try:
                if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        else:
            pytest.fail("openpi server did not come up")
        yield port, log
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def _requests(log: Path) -> list[dict]:
    return [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []


def test_axis_angle_keeps_the_quaternion_sign_like_robosuite():
    half = np.sqrt(0.5)
    assert np.allclose(quat_xyzw_to_axis_angle(np.array([half, 0, 0, half])), [np.pi / 2, 0, 0])
    # q and -q are the same rotation but robosuite's formula (and so the policy) tells them apart
    assert np.allclose(quat_xyzw_to_axis_angle(np.array([-half, 0, 0, -half])), [-3 * np.pi / 2, 0, 0])
    assert np.allclose(quat_xyzw_to_axis_angle(np.array([0, 0, 0, 1.0])), 0)


def test_rotate_180_sends_robosuites_raw_image_turned_180_degrees():
    ours = np.arange(4 * 4 * 3, dtype=np.uint8).reshape(4, 4, 3)
    robosuite_raw = ours[::-1]  # robosuite renders upside down
    assert np.array_equal(prepare_image(ours, 4, rotate_180=True), robosuite_raw[::-1, ::-1])
    assert np.array_equal(prepare_image(ours, 4, rotate_180=False), ours)
    assert prepare_image(ours, 8, rotate_180=True).shape == (8, 8, 3)


def test_client_refuses_to_start_without_a_server():
    with pytest.raises(FatalError, match="unreachable"):
        OpenpiPolicy(OpenpiPolicyConfig(port=_free_port()))


@pytest.mark.sim
def test_libero_episode_runs_through_a_real_openpi_server(server, libero_spatial_env):
    port, log = server
    env = libero_spatial_env
    before = len(_requests(log))
    policy = OpenpiPolicy(OpenpiPolicyConfig(port=port, image_size=224), name="pi-test")
    assert policy.server_metadata == {"policy": "state-controller", "chunk": 8}
    try:
        env.reset_to_init(0)
        env.settle(10)
        policy.reset(env.task, 0)
        obs0 = observe(env, policy, 0)
        sent0 = policy.request(obs0)
        start = env.eef_pose()[0]
        result = run_episode(env, policy, horizon=24, chunk_size=8, stop_on_success=False)
    finally:
        policy.close()
    got = _requests(log)[before:]
    assert result.steps == 24 and len(got) == 3  # one query per 8-step chunk
    first = got[0]
    assert first["prompt"] == env.task.instruction
    for key in ("observation/image", "observation/wrist_image"):
        assert first[key]["shape"] == [224, 224, 3] and first[key]["dtype"] == "uint8"
        assert first[key]["sha"] == digest(sent0[key])  # the bytes arrived unchanged
    assert np.allclose(first["state"], sent0["observation/state"])
    assert len(first["state"]) == 8
    # the served controller drives the gripper toward its target: the actions were applied
    end = env.eef_pose()[0]
    assert np.linalg.norm(end - TARGET) < np.linalg.norm(start - TARGET) - 0.02


@pytest.mark.sim
def test_state_uses_robosuites_eef_quaternion(libero_spatial_env):
    env = libero_spatial_env
    env.reset_to_init(1)
    env.settle(5)
    robosuite_quat = env.env._get_observations(force_update=True)["robot0_eef_quat"]
    assert np.allclose(env.eef_hand_quat(), robosuite_quat)

    class NoSim:
        cameras, image_size = (), 224

    obs = observe(env, NoSim(), 0)
    with_sim = libero_state(obs)
    obs.sim = None  # the fallback derives the same rotation from the grip site
    without = libero_state(obs)
    assert np.allclose(with_sim[:3], without[:3]) and np.allclose(with_sim[6:], without[6:])

    def rotation(aa):
        from scipy.spatial.transform import Rotation

        return Rotation.from_rotvec(aa).as_matrix()

    assert np.allclose(rotation(with_sim[3:6]), rotation(without[3:6]), atol=1e-5)


@pytest.mark.sim
def test_stage1_runs_an_openpi_policy_from_the_config(server, tmp_path):
    from pipeline.stage1.run import run

    port, _ = server
    cfg = load_config(
        "configs/smoke.yaml",
        {
            "run.output_dir": str(tmp_path / "run"),
            "tasks.suites": ["libero_spatial"],
            "tasks.init_states": [0],
            "executor.workers": 1,
            "stage1.policy.kind": "openpi",
            "stage1.policy.name": "pi-remote",
            "stage1.policy.openpi.port": port,
            "stage1.rollout.horizon": 16,
            "stage1.video.render": "none",
        },
    )
    result = run(cfg)
    assert result["done"] == 1 and not result["errors"]
    (rec,) = read_episodes(tmp_path / "run" / "stage1" / "episodes.parquet")
    assert rec.policy == "pi-remote" and rec.policy_kind == "openpi" and rec.steps == 16
    assert rec.policy_params["port"] == port and rec.policy_params["server_metadata"]["chunk"] == 8


@pytest.fixture(scope="module")
def libero_spatial_env():
    from pipeline.sim import SimEnv, tasks

    env = SimEnv(tasks(["libero_spatial"])[0])
    yield env
    env.close()


@pytest.mark.sim
def test_temporal_context_arrives_frame_exact_at_a_real_openpi_server(server, libero_spatial_env, tmp_path):
    """Both of the reference's temporal variants, built by the eval's own `temporal_context`
    and sent by the shipped client: the server logs what arrived, compared with frames
    rendered here independently from the same states."""
    from types import SimpleNamespace

    from pipeline.eval.protocol import temporal_context

    port, log = server
    env = libero_spatial_env
    env.reset_to_init(0)
    states, rows = [], {"eef_pos": [], "eef_quat": [], "gripper_qpos": []}
    for t in range(10):  # a short "pre-failure" window: the arm rises
        states.append(env.get_state())
        obs = observe(env, SimpleNamespace(cameras=(), image_size=224), t)
        rows["eef_pos"].append(obs.eef_pos)
        rows["eef_quat"].append(obs.eef_quat)
        rows["gripper_qpos"].append(obs.gripper_qpos)
        env.step(np.array([0, 0, 0.5, 0, 0, 0, -1.0]))
    history = tmp_path / "step_0010_history.npz"
    np.savez(history, steps=np.arange(10, dtype=np.int32), sim_states=np.asarray(states),
             **{k: np.asarray(v, dtype=np.float32) for k, v in rows.items()})
    scene = SimpleNamespace(init_state=0, episode_id="scripted-i00-s0", history_paths=(history,))
    policy = OpenpiPolicy(OpenpiPolicyConfig(port=port, image_size=224), name="pi-context")
    cfg = policy.cfg
    try:
        for kind in ("initial_frame", "history"):
            trial = SimpleNamespace(temporal_context=kind, mode="scene", scene=scene)
            context = temporal_context(env, policy, trial)
            env.reset_to(states[-1])
            policy.reset(env.task, 0)
            before = len(_requests(log))
            policy.act(observe(env, policy, 0, context))
            (got,) = _requests(log)[before:]
            assert got["temporal_context"] == kind
            if kind == "initial_frame":
                env.reset_to(env.task.init_states()[0])
                for cam, key in (("agentview", "image"), ("robot0_eye_in_hand", "wrist_image")):
                    want = prepare_image(env.render(cam, 256), 224, cfg.rotate_180)
                    assert got[f"observation/initial_{key}"] == {"shape": [224, 224, 3], "dtype": "uint8",
                                                                 "sha": digest(want)}
            else:
                frames = env.render_states(np.asarray(states[-8:]), ["agentview", "robot0_eye_in_hand"], 256)
                for cam, key in (("agentview", "image"), ("robot0_eye_in_hand", "wrist_image")):
                    want = np.stack([prepare_image(f, 224, cfg.rotate_180) for f in frames[cam]])
                    assert got[f"observation/history_{key}"]["shape"] == [8, 224, 224, 3]
                    assert got[f"observation/history_{key}"]["sha"] == digest(want)  # the 8 frames, exact
                assert got["observation/history_steps"]["sha"] == digest(np.arange(2, 10, dtype=np.int32))
                assert got["observation/history_state"]["shape"] == [8, 8]
    finally:
        policy.close()
