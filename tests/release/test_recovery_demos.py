"""Recovery demonstrations: recovery-expert rollouts from released scenes, recorded as in stage 1,
exported as a LeRobot v2.1 dataset that LeRobot's own `LeRobotDataset` opens."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import pipeline.release.recovery_demos as demos_mod
from pipeline.release.build import build
from pipeline.release.lerobot_export import run as export
from pipeline.release.recovery_demos import read_demos
from tests.release.factories import make_run, npy_bytes, release_config
from tests.release.test_lerobot_export import READER_PYTHON

pytestmark = pytest.mark.sim

SIZE = 64
CAMS = ["observation.images.image", "observation.images.image2"]


def _config(run: Path, **release):
    # every scene on the train side (one scene: nothing to hold out); test_split covers the split
    cfg = release_config(run, **{"certify_horizon": 300, "recovery_demo_tries": 3, "lerobot_image_size": SIZE,
                                 "split": {"train_share": 1.0}, **release})
    video = cfg.stage1.video.model_copy(update={"resolution": SIZE})
    return cfg.model_copy(update={"stage1": cfg.stage1.model_copy(update={"video": video})})


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, scene_source):
    run = make_run(tmp_path_factory.mktemp("run"), scene_source,
                   {"ep-a": (npy_bytes(scene_source.failure), scene_source.bddl_text)})
    cfg = _config(run, recovery_demos=2)
    build(cfg)
    return cfg, demos_mod.run(cfg)


def test_demos_are_successful_rollouts_logged_and_rendered_like_stage1(recorded, monkeypatch):
    cfg, root = recorded
    demos = read_demos(root / "demos.parquet")
    assert [d.demo_index for d in demos] == [0, 1]
    assert demos[0].scene_id.startswith("libero_spatial/") and demos[0].scene_id.endswith("/ep-a/step_0024")
    assert (demos[0].level, demos[0].category) == ("L2", "grasp_failure")
    assert demos[0].seed != demos[1].seed and demos[0].variation == 0.5
    for d in demos:
        folder = root / d.path
        states = np.load(folder / "states.npy")
        steps = pq.read_table(folder / "steps.parquet")
        assert states.shape == (d.steps + 1, d.state_dim) and steps.num_rows == d.steps
        assert steps.column("goal").to_pylist()[-1] is True  # it ended on the goal: a success
        assert sorted(d.videos) == ["agentview", "robot0_eye_in_hand"] and d.video_fps == cfg.stage1.video.fps
        assert all((folder / f).is_file() for f in d.videos.values()) and (folder / "frames.parquet").is_file()
    assert not np.array_equal(np.load(root / demos[0].path / "states.npy")[-1],
                              np.load(root / demos[1].path / "states.npy")[-1])  # seeded variation
    (line,) = [json.loads(x) for x in (root / "scenes.jsonl").read_text().splitlines()]
    assert line["demos"] == 2 and line["tries"] == 2 + sum(line["failed"].values())
    assert line["unreplayable"] == 0  # every kept demo replayed in plain LIBERO
    # done scenes are not redone
    monkeypatch.setattr(demos_mod, "attempt", lambda *a, **k: pytest.fail("a done scene was recorded again"))
    demos_mod.run(cfg)
    assert len(read_demos(root / "demos.parquet")) == 2


def test_verify_replay_counts_every_demo_and_names_a_corrupted_action_file(recorded, tmp_path):
    import shutil

    from pipeline.release.build import release_dir
    from pipeline.release.replay import verify_demos

    cfg, root = recorded
    rep = verify_demos(release_dir(cfg), root)
    assert (rep.recorded, rep.replayed, rep.identical, rep.goal_at_step, rep.dropped) == (2, 2, 2, 2, 0)
    assert rep.ok and rep.problems == []
    copy = tmp_path / "recoveries"
    shutil.copytree(root, copy)
    demo = copy / read_demos(root / "demos.parquet")[1].path
    actions = np.load(demo / "actions.npy")
    # one float32 ulp on an arm command the controller does not clip away (not 0, not +-1)
    t, i = next((t, i) for t in range(len(actions)) for i in range(6) if 0.01 < abs(actions[t, i]) < 0.99)
    actions[t, i] = np.nextafter(np.float32(actions[t, i]), np.float32(-np.inf))
    np.save(demo / "actions.npy", actions)
    rep = verify_demos(release_dir(cfg), copy)
    assert (rep.replayed, rep.identical) == (2, 1) and not rep.ok
    assert rep.problems[0].startswith(f"{demo / 'actions.npy'}: replayed in plain LIBERO, the state after step {t + 1}")


def test_unsuccessful_tries_are_counted_not_kept(tmp_path, scene_source):
    run = make_run(tmp_path / "run", scene_source, {"ep-a": (npy_bytes(scene_source.failure), scene_source.bddl_text)})
    cfg = _config(run, recovery_demos=1, recovery_demo_tries=2, certify_horizon=3)
    build(cfg)
    root = demos_mod.run(cfg)
    assert read_demos(root / "demos.parquet") == []
    (line,) = [json.loads(x) for x in (root / "scenes.jsonl").read_text().splitlines()]
    assert (line["tries"], line["demos"], line["failed"]) == (2, 0, {"timeout": 2})
    assert not any((root / "episodes").rglob("states.npy"))


def test_export_writes_the_recoveries_dataset_and_lerobot_opens_it(recorded, tmp_path):
    cfg, root = recorded
    demos = read_demos(root / "demos.parquet")
    out = export(cfg, tmp_path / "lerobot", only=["recoveries"])
    assert not (out / "rollouts").exists()
    ds = out / "recoveries"
    info = json.loads((ds / "meta/info.json").read_text())
    frames = sum(d.steps for d in demos)
    assert (info["codebase_version"], info["fps"], info["total_episodes"], info["total_frames"]) == (
        "v2.1", 20, 2, frames)
    episodes = [json.loads(x) for x in (ds / "meta/episodes.jsonl").read_text().splitlines()]
    assert [e["scene_id"] for e in episodes] == [d.scene_id for d in demos]
    assert {(e["level"], e["category"]) for e in episodes} == {("L2", "grasp_failure")}
    assert {t for e in episodes for t in e["tasks"]} == {demos[0].instruction}
    actions = np.array(pq.read_table(ds / "data/chunk-000/episode_000001.parquet").column("action").to_pylist())
    logged = np.array(pq.read_table(root / demos[1].path / "steps.parquet").column("action").to_pylist())
    assert np.allclose(actions, logged)

    if not READER_PYTHON.is_file():
        pytest.fail(f"LeRobot reader environment missing ({READER_PYTHON}); build it with `make setup-test`")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf")}
    last = frames - 1
    res = subprocess.run([str(READER_PYTHON), str(Path(__file__).with_name("lerobot_reader.py")), str(ds),
                          str(tmp_path / "work"), "0", str(last)], capture_output=True, text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-4000:]
    got = json.loads(res.stdout)
    assert (got["len"], got["num_episodes"], got["fps"], got["tasks"]) == (frames, 2, 20, [demos[0].instruction])
    assert sorted(got["video_keys"]) == CAMS
    assert got["episode_meta"]["scene_id"] == [d.scene_id for d in demos]
    assert got["episode_meta"]["level"] == ["L2", "L2"]
    end = got["frames"][1]
    assert (end["episode_index"], end["frame_index"]) == (1, demos[1].steps - 1)
    assert np.allclose(end["action"], logged[-1], atol=1e-6)
    for key in CAMS:
        assert end[key]["shape"] == [3, SIZE, SIZE] and end[key]["std"] > 0.02
