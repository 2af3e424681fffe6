"""LeRobot v2.1 export: layout, 20 Hz frames rendered from states, and LeRobot tools read it."""

from __future__ import annotations

import base64
import json
import os
import subprocess
import sys
from pathlib import Path

import av
import numpy as np
import pyarrow.parquet as pq
import pytest

import pipeline.release.lerobot_export as lerobot_export
from pipeline.errors import FatalError
from pipeline.release.build import build
from pipeline.release.lerobot_export import run as export
from tests.release.factories import make_run, npy_bytes, release_config

pytestmark = pytest.mark.sim

SIZE = 64
REPO = Path(__file__).resolve().parents[2]
# LeRobot's own reader lives in its own environment (it needs numpy 2; ours pins numpy < 2)
READER_PYTHON = Path(os.environ.get("LEROBOT_READER_PYTHON", REPO / ".venv-lerobot/bin/python"))


@pytest.fixture(scope="module")
def exported(tmp_path_factory, scene_source) -> tuple[Path, object]:
    good = npy_bytes(scene_source.failure)
    run = make_run(tmp_path_factory.mktemp("run"), scene_source,
                   {"ep-a": (good, scene_source.bddl_text), "ep-b": (good, scene_source.bddl_text)})
    cfg = release_config(run, lerobot_image_size=SIZE)
    build(cfg)
    assert (cfg.executor.kind, cfg.executor.workers) == ("local", 2)  # 2 worker processes, one episode each
    return export(cfg), scene_source


def test_export_writes_the_v21_layout(exported):
    out, src = exported
    root = out / "rollouts"
    info = json.loads((root / "meta/info.json").read_text())
    assert info["codebase_version"] == "v2.1" and info["fps"] == 20
    assert (info["total_episodes"], info["total_frames"], info["total_videos"]) == (2, 48, 4)
    assert info["features"]["observation.state"]["shape"] == [8]
    assert info["features"]["observation.states.joint_state"] == {
        "dtype": "float32", "shape": [7], "names": [f"joint_{i}" for i in range(7)]}
    assert info["features"]["observation.states.gripper_state"]["shape"] == [2]
    assert info["features"]["action"]["shape"] == [7]
    # two scenes of one suite x level: at least one is held out, and its rollout with it
    assert info["splits"].get("eval", "").endswith(":2") and info["splits"].get("train", "0:0").startswith("0:")
    for ep in (0, 1):
        assert (root / f"data/chunk-000/episode_{ep:06d}.parquet").is_file()
        for key in ("observation.images.image", "observation.images.image2"):
            assert (root / f"videos/chunk-000/{key}/episode_{ep:06d}.mp4").is_file()
    episodes = [json.loads(x) for x in (root / "meta/episodes.jsonl").read_text().splitlines()]
    # where each began: LIBERO's init state 0 of the task, then 10 settle steps (make_run's episodes)
    assert episodes == [{"episode_index": i, "tasks": [src.task.instruction], "length": 24, "init_state": 0,
                         "settle_steps": 10} for i in (0, 1)]
    assert [json.loads(x) for x in (root / "meta/tasks.jsonl").read_text().splitlines()] == [
        {"task_index": 0, "task": src.task.instruction}]
    stats = [json.loads(x) for x in (root / "meta/episodes_stats.jsonl").read_text().splitlines()]
    assert np.array(stats[0]["stats"]["observation.images.image"]["mean"]).shape == (3, 1, 1)


def test_export_frames_follow_the_logged_states_and_actions(exported):
    out, src = exported
    table = pq.read_table(out / "rollouts/data/chunk-000/episode_000001.parquet")
    assert table.column("index").to_pylist() == list(range(24, 48))
    assert np.allclose(table.column("timestamp").to_numpy(), np.arange(24) / 20)
    actions = np.array(table.column("action").to_pylist())
    assert np.allclose(actions, np.array(src.steps_table.column("action").to_pylist()))
    # beside the float32 column, the actions exactly as stepped: they replay bit for bit
    assert np.array_equal(np.array(table.column("action_float64").to_pylist()), src.actions)
    assert np.array_equal(actions, src.actions.astype(np.float32))
    state = np.array(table.column("observation.state").to_pylist())
    eef = np.array(src.steps_table.column("eef_pos").to_pylist())
    # the step log holds the pose MuJoCo computed before the last substep's integration; the
    # export recomputes it for the exact logged state, so they agree to within a substep
    assert np.allclose(state[:, :3], eef, atol=1e-3)
    assert np.array_equal(state[0, :3].round(6), eef[0].round(6))
    assert state[8, 2] > state[0, 2] + 0.05  # the arm went up
    # the arm's joint states, from the logged MuJoCo states (qpos: the 7 arm joints, then the fingers)
    joints = np.array(table.column("observation.states.joint_state").to_pylist())
    assert np.allclose(joints, src.states[:24, 1:8], atol=1e-6)
    assert not np.allclose(joints[0], joints[8], atol=1e-3)  # they moved as the arm went up
    fingers = np.array(table.column("observation.states.gripper_state").to_pylist())
    assert np.array_equal(fingers, state[:, 6:8]) and np.allclose(fingers, src.states[:24, 8:10], atol=1e-6)
    with av.open(str(out / "rollouts/videos/chunk-000/observation.images.image/episode_000001.mp4")) as c:
        s = c.streams.video[0]
        frames = list(c.decode(s))
        assert (len(frames), s.average_rate, frames[0].width) == (24, 20, SIZE)


def test_export_holds_each_released_scene_history_up_to_its_failure(exported):
    out, _ = exported
    info = json.loads((out / "pre_failure_histories/meta/info.json").read_text())
    assert (info["total_episodes"], info["total_frames"]) == (2, 40)  # fail_step 20 in each


def test_lerobot_doctor_reads_the_export_without_failures(exported):
    out, _ = exported
    for name in ("rollouts", "pre_failure_histories"):
        res = subprocess.run([sys.executable, "-m", "lerobot_doctor.cli", "check", str(out / name), "--json"],
                             capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr[-2000:]
        report = json.loads(res.stdout)
        assert (report["format_version"], report["codebase_version"]) == ("v2", "v2.1")
        severity = {c["name"]: c["severity"] for c in report["checks"]}
        # format, timing, videos and features must pass; data-quality warnings about the toy
        # episodes (few distinct actions) are about content, not the format
        for check in ("Metadata & Format Compliance", "Temporal Consistency", "Video Integrity",
                      "Feature Consistency", "Portability"):
            assert severity[check] == "PASS", (check, res.stdout[-3000:])
        assert "FAIL" not in severity.values(), severity
        messages = [m["message"] for c in report["checks"] for m in c["messages"]]
        assert not any("stats.json not found" in m for m in messages)


def test_lerobots_own_dataset_class_opens_the_export(exported, tmp_path):
    out, src = exported
    if not READER_PYTHON.is_file():
        pytest.fail(f"LeRobot reader environment missing ({READER_PYTHON}); build it with `make setup-test` "
                    "(or `bash scripts/setup_lerobot.sh`)")
    root = out / "rollouts"
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf")}
    # frame 30 = episode 1, frame 6: checks LeRobot's episode -> video offsets, not just the first frame
    res = subprocess.run([str(READER_PYTHON), str(Path(__file__).with_name("lerobot_reader.py")), str(root),
                          str(tmp_path / "work"), "0", "30"], capture_output=True, text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-4000:]
    got = json.loads(res.stdout)
    assert (got["converted_version"], got["len"], got["num_frames"], got["num_episodes"], got["fps"]) == (
        "v3.0", 48, 48, 2, 20)
    assert got["episode_lengths"] == [24, 24] and got["tasks"] == [src.task.instruction]
    assert got["features"]["observation.state"] == {"dtype": "float32", "shape": [8]}
    assert got["features"]["observation.states.joint_state"] == {"dtype": "float32", "shape": [7]}
    assert got["features"]["observation.states.gripper_state"] == {"dtype": "float32", "shape": [2]}
    assert got["features"]["action"] == {"dtype": "float32", "shape": [7]}
    assert got["features"]["action_float64"] == {"dtype": "float64", "shape": [7]}
    cams = ["observation.images.image", "observation.images.image2"]
    assert sorted(got["video_keys"]) == cams
    table = pq.read_table(root / "data/chunk-000/episode_000001.parquet")
    first, mid = got["frames"]
    assert (mid["index"], mid["episode_index"], mid["frame_index"]) == (30, 1, 6)
    assert mid["timestamp"] == pytest.approx(6 / 20) and mid["task"] == src.task.instruction
    assert np.allclose(mid["state"], table.column("observation.state")[6].as_py(), atol=1e-6)
    assert np.allclose(mid["observation.states.joint_state"],
                       table.column("observation.states.joint_state")[6].as_py(), atol=1e-6)
    assert np.allclose(mid["action"], table.column("action")[6].as_py(), atol=1e-6)
    for key in cams:
        for frame in (first, mid):
            img = frame[key]
            assert img["shape"] == [3, SIZE, SIZE] and img["dtype"] == "torch.float32"
            assert img["std"] > 0.02 and img["max"] - img["min"] > 0.2, (key, img)  # a real picture, not blank
        # LeRobot's decoded frame is the MP4's frame 6 of episode 1 (our own decode of the same file)
        with av.open(str(root / f"videos/chunk-000/{key}/episode_000001.mp4")) as c:
            ours = [f.to_ndarray(format="rgb24") for f in c.decode(c.streams.video[0])]
        theirs = np.frombuffer(base64.b64decode(mid[key]["rgb24"]), np.uint8).reshape(SIZE, SIZE, 3)
        diff = [np.abs(theirs.astype(int) - f.astype(int)).mean() for f in ours]
        assert diff[6] < 0.5 and int(np.argmin(diff)) == 6, (key, diff)


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_one_worker_writes_the_same_dataset_byte_for_byte(exported, tmp_path):
    out, _ = exported  # 2 workers: the group of two episodes (one model) was split across them
    cfg = release_config(out.parent, lerobot_image_size=SIZE)
    one = cfg.model_copy(update={"executor": cfg.executor.model_copy(update={"kind": "inline"})})  # this process
    single = export(one, tmp_path / "one", only=["rollouts"])
    ours, theirs = _files(out / "rollouts"), _files(single / "rollouts")
    assert sorted(ours) == sorted(theirs) and len(ours) == 4 + 2 + 5  # 4 videos, 2 parquet, 5 meta files
    assert ours == theirs  # repeatable H.264 (pipeline.h264): the same frames, the same MP4 bytes
    for name in ("000000.json", "000001.json"):
        assert (out / "_work/rollouts" / name).read_bytes() == (single / "_work/rollouts" / name).read_bytes()


def test_a_failing_episode_is_set_aside_and_a_rerun_does_only_what_is_missing(tmp_path, scene_source, monkeypatch):
    good = npy_bytes(scene_source.failure)
    run = make_run(tmp_path / "run", scene_source, {"ep-a": (good, scene_source.bddl_text),
                                                    "ep-b": (good, scene_source.bddl_text)})
    cfg = release_config(run, lerobot_image_size=SIZE)
    cfg = cfg.model_copy(update={"executor": cfg.executor.model_copy(update={"kind": "inline"})})  # patchable
    states = next((run / "stage1/episodes").rglob("ep-b/states.npy"))
    intact = states.read_bytes()
    states.write_bytes(b"not an array")
    with pytest.raises(FatalError, match=r"rollouts: 1 episode\(s\) set aside.*000001: .*ep-b"):
        export(cfg, only=["rollouts"])
    root = run / "lerobot/rollouts"
    assert (root / "data/chunk-000/episode_000000.parquet").is_file()  # the other episode went on
    assert not (root / "meta").exists()  # no meta for an incomplete dataset
    states.write_bytes(intact)
    rendered = []
    real = lerobot_export.export_episode
    monkeypatch.setattr(lerobot_export, "export_episode",
                        lambda env, ep, i, *a: rendered.append(i) or real(env, ep, i, *a))
    export(cfg, only=["rollouts"])
    assert rendered == [1]
    assert json.loads((root / "meta/info.json").read_text())["total_episodes"] == 2
