"""One recorded episode in a real LIBERO environment: what is logged is what happened."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.atomic import Completions
from pipeline.config import Config
from pipeline.errors import ConfigError
from pipeline.stage1.run import _check_resumable
from pipeline.stage1.units import plan_units
from pipeline.stage1.video import read_video
from pipeline.stage1.worker import run_one, should_render
from toy_policy import DriftPolicy


def _cfg(tmp_path, **stage1) -> Config:
    return Config.model_validate(
        {
            "run": {"output_dir": str(tmp_path), "seed": 1},
            "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": [4]},
            "stage1": {
                "policy": {"name": "drift"},
                "rollout": {"horizon": 13, "chunk_size": 4, "settle_steps": 3},
                "video": {"cameras": ["agentview", "robot0_eye_in_hand"], "fps": 5, "resolution": 64, "render": "all"},
                **stage1,
            },
        }
    )


@pytest.fixture(scope="module")
def env():
    from pipeline.sim import SimEnv, tasks

    e = SimEnv(tasks(["libero_spatial"])[0])
    yield e
    e.close()


@pytest.mark.sim
def test_logged_states_replay_bit_identically_from_the_logged_actions(env, tmp_path):
    cfg = _cfg(tmp_path)
    (unit,) = plan_units(cfg)
    rec = run_one(env, DriftPolicy(), unit, cfg, tmp_path / "stage1")
    folder = tmp_path / "stage1" / rec.path
    states = np.load(folder / "states.npy")
    steps = pq.read_table(folder / "steps.parquet").to_pylist()
    assert rec.steps == 13 and len(steps) == 13 and states.shape == (14, env.state_dim)
    assert [s["query"] for s in steps] == [i % 4 == 0 for i in range(13)]
    assert rec.seed == unit.seed and rec.init_state == 4 and not rec.success

    # row 0 is the state after reset + settle, before the first action
    env.reset_to_init(4)
    env.settle(3)
    assert np.array_equal(env.get_state(), states[0])
    for t, row in enumerate(steps):
        assert np.allclose(env.eef_pose()[0], row["eef_pos"], atol=1e-6)
        assert np.allclose(env.gripper_qpos(), row["gripper_qpos"], atol=1e-6)
        env.step(np.asarray(row["action"], dtype=np.float64))  # float32-exact actions
        assert np.array_equal(env.get_state(), states[t + 1])

    # videos: 13 steps at 5 fps -> frames at steps 0, 4, 8, 12 and the final state 13
    frames = pq.read_table(folder / "frames.parquet").to_pylist()
    assert [f["step"] for f in frames] == [0, 4, 8, 12, 13]
    for cam in ("agentview", "robot0_eye_in_hand"):
        video = read_video(folder / rec.videos[cam])
        assert len(video) == 5
        env.set_state(states[8])
        expected = env.render(cam, 64, cfg.stage1.video.quality).astype(float)
        assert np.abs(video[2].astype(float) - expected).mean() < 8  # lossy, but the same picture


def test_successes_get_no_video_by_default_failures_do():
    assert should_render("failures", success=False) and not should_render("failures", success=True)
    assert should_render("all", success=True) and not should_render("none", success=False)


def test_resuming_into_a_folder_of_another_experiment_is_refused(tmp_path):
    from pipeline.config import save_resolved

    old = _cfg(tmp_path)
    stage1 = tmp_path / "stage1"
    save_resolved(old, stage1)
    Completions(stage1).mark_done("some_unit", {})
    _check_resumable(old.model_copy(), stage1)  # same experiment: fine
    changed = _cfg(tmp_path, rollout={"horizon": 99})
    with pytest.raises(ConfigError, match="different run seed/policy/rollout"):
        _check_resumable(changed, stage1)
    # video settings may change between resumptions (e.g. render successes later)
    _check_resumable(_cfg(tmp_path, video={"render": "failures"}), stage1)


@pytest.mark.sim
def test_review_videos_of_both_cameras_at_256_px_leave_the_states_byte_identical(env, tmp_path):
    # videos are rendered from the logged states afterwards: neither the episode's states nor
    # the next episode's depend on what (or whether) was rendered
    got = []
    for name, video in (("none", {"render": "none"}),
                        ("both256", {"cameras": ["agentview", "robot0_eye_in_hand"], "resolution": 256,
                                     "render": "all"}),
                        ("after", {"render": "none"})):
        cfg = _cfg(tmp_path / name, video={"fps": 5, **video})
        (unit,) = plan_units(cfg)
        rec = run_one(env, DriftPolicy(), unit, cfg, tmp_path / name / "stage1")
        got.append((tmp_path / name / "stage1" / rec.path / "states.npy").read_bytes())
        assert bool(rec.videos) == (name == "both256")
    assert got[0] == got[1] == got[2]
