"""Reproduction: the smoke pipeline run twice from scratch gives byte-identical scene files.

Drives the real CLI: `recover stage1`, `recover stage2` on a tiny config, final annotations
for the localized episodes (the reviewed labels are inputs), `recover release`, then
`recover reproduce`, which re-runs stages 1-2 into a fresh folder, re-releases with the
stored annotations and compares every file's checksum.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.atomic import write_json
from pipeline.records import Localization
from pipeline.release.reproduce import compare, file_sums
from tests.release.factories import annotation

pytestmark = [pytest.mark.sim, pytest.mark.slow]


def recover(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).parent / "recover"
    res = subprocess.run([str(exe), *args], cwd=cwd, capture_output=True, text=True, timeout=1500)
    assert res.returncode == 0 or args[0] in ("verify", "reproduce"), (args, res.stdout[-3000:], res.stderr[-3000:])
    return res


def tiny_config(path: Path, run: Path) -> Path:
    cfg = {
        "run": {"name": "tiny", "output_dir": str(run), "seed": 0},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": [0, 1]},
        "executor": {"kind": "local", "workers": 1},
        "stage1": {"policy": {"kind": "scripted", "scripted": {"noise": {
            "grasp_offset_m": 0.03, "approach_height_m": 0.02, "gripper_timing_steps": 6, "action_noise": 0.1}}},
            "rollout": {"horizon": 120, "chunk_size": 8},
            "video": {"cameras": ["agentview"], "fps": 5, "resolution": 64}},
        "stage2": {"history_frames": 2},
        "release": {"certify_tries": 0},
    }
    path.write_text(yaml.safe_dump(cfg))
    return path


def annotate_all(run: Path) -> int:
    """Final annotations for every localized episode (as if people had reviewed them)."""
    n = 0
    for f in sorted((run / "stage2" / "localizations").rglob("*.json")):
        loc = Localization.model_validate_json(f.read_text())
        write_json(run / "stage3" / "annotations" / loc.suite / loc.task / f"episode_{loc.episode_id}.json",
                   annotation(loc.suite, loc.task, loc.episode_id, loc.instruction, loc.fail_step))
        n += 1
    return n


@pytest.fixture(scope="module")
def smoke(tmp_path_factory) -> dict:
    """stage1 -> stage2 -> (annotations) -> release -> verify -> reproduce, once, via the CLI."""
    root = Path(__file__).resolve().parents[2]
    tmp = tmp_path_factory.mktemp("smoke")
    run = tmp / "run"
    config = tiny_config(tmp / "tiny.yaml", run)
    recover("stage1", "--config", str(config), cwd=root)
    recover("stage2", "--config", str(config), cwd=root)
    assert annotate_all(run) >= 1, "the tiny config produced no localized failure"
    recover("release", "--config", str(config), cwd=root)
    verify = recover("verify", str(run / "release"), cwd=root)
    reproduce = recover("reproduce", "--config", str(config), cwd=root)
    return {"stored": run / "release", "rebuilt": tmp / "run.reproduce" / "release", "verify": verify,
            "reproduce": reproduce}


def test_two_runs_from_scratch_give_byte_identical_scene_pairs(smoke):
    diffs = dict(compare(smoke["stored"], smoke["rebuilt"]))
    pairs = [p for p in file_sums(smoke["stored"]) if p.endswith((".bddl", "_sim_state.npy"))]
    assert pairs and not [p for p in pairs if p in diffs], diffs


def test_two_runs_from_scratch_give_identical_checksums_for_every_file(smoke):
    assert compare(smoke["stored"], smoke["rebuilt"]) == [], smoke["reproduce"].stdout[-3000:]
    assert smoke["reproduce"].returncode == 0 and "byte-identical" in smoke["reproduce"].stdout


def test_the_smoke_release_passes_verify(smoke):
    assert smoke["verify"].returncode == 0, smoke["verify"].stdout[-3000:]


def test_compare_names_each_file_that_differs(tmp_path, scene_source):
    from pipeline.release.build import build
    from tests.release.factories import make_run, npy_bytes, release_config

    scenes = {"ep-a": (npy_bytes(scene_source.failure), scene_source.bddl_text)}
    first, second = make_run(tmp_path / "a", scene_source, scenes), make_run(tmp_path / "b", scene_source, scenes)
    rows = build(release_config(first))
    build(release_config(second))
    assert compare(first / "release", second / "release") == []
    source = next((second / "stage2").rglob("*_sim_state.npy"))  # a rerun whose stage 2 came out different
    data = bytearray(source.read_bytes())
    data[-1] ^= 0xFF
    source.write_bytes(bytes(data))
    build(release_config(second))
    diffs = compare(first / "release", second / "release")
    # the state file, and the manifest that holds its hash; nothing else
    assert sorted(d[0] for d in diffs) == sorted([rows[0].state_path, "scenarios.parquet"])
    assert all(status.startswith("differs (") for _, status in diffs)


def test_a_reviewed_onset_is_released_from_a_new_snapshot_at_the_first_settled_step_after_it(smoke, tmp_path):
    import shutil

    import numpy as np

    from pipeline.config import Stage2Config
    from pipeline.release.sources import gather

    run = tmp_path / "run"
    shutil.copytree(smoke["stored"].parent, run, ignore=shutil.ignore_patterns("release"))
    ann_file = next((run / "stage3" / "annotations").rglob("episode_*.json"))
    ann = json.loads(ann_file.read_text())
    loc = Localization.model_validate_json(
        (run / "stage2" / "localizations" / ann["suite"] / ann["task"] / f"{ann['episode_id']}.json").read_text())
    # reviewers put the onset 10 steps (0.5 s) after the model's
    reviewed = loc.fail_step + 10
    ann.update(fail_step=reviewed, fail_time_s=reviewed / 20)
    ann_file.write_text(json.dumps(ann))
    items, skipped = gather(run, Stage2Config(history_frames=2))
    item = next(i for i in items if i.annotation.key == ann["key"])
    assert not [s for s in skipped if s.key == ann["key"]]
    assert "reviewed_scenes" in item.scene_state.parts and item.step >= reviewed
    states = np.load(next((run / "stage1" / "episodes").rglob(f"{ann['episode_id']}/states.npy")))
    np.testing.assert_array_equal(np.load(item.scene_state), states[item.step])
    assert item.scene_bddl.read_text() == (run / "stage2" / loc.scene_bddl).read_text()
    history = np.load(item.history)
    assert history["steps"].tolist() == [reviewed - 2, reviewed - 1]
    # an annotation that keeps the model's onset keeps stage 2's scene
    ann.update(fail_step=loc.fail_step, fail_time_s=loc.fail_step / 20)
    ann_file.write_text(json.dumps(ann))
    items, _ = gather(run, Stage2Config(history_frames=2))
    item = next(i for i in items if i.annotation.key == ann["key"])
    assert item.scene_state == run / "stage2" / loc.scene_state
