"""`recover release`: layout, manifest, card, determinism, quarantine, stale files."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from pipeline.release.build import build
from pipeline.release.manifest import MANIFEST_NAME, read_manifest
from tests.release.factories import make_run, npy_bytes, release_config

pytestmark = pytest.mark.sim  # the scene source is a real episode


@pytest.fixture()
def run(tmp_path, scene_source) -> Path:
    good = npy_bytes(scene_source.failure)
    return make_run(tmp_path / "run", scene_source, {"ep-a": (good, scene_source.bddl_text),
                                                     "ep-b": (good, scene_source.bddl_text)})


def test_release_lays_out_scene_pairs_history_manifest_and_card(run):
    rows = build(release_config(run))
    out = run / "release"
    assert [r.episode_id for r in rows] == ["ep-a", "ep-b"]
    r = rows[0]
    assert r.bddl_path == (f"selected_bddl_scenes_libero_spatial/{r.task}/episode_ep-a/step_{r.step:04d}.bddl")
    assert r.state_path == r.bddl_path.removesuffix(".bddl") + "_sim_state.npy"
    assert r.history_paths == [r.bddl_path.removesuffix(".bddl") + "_history.npy"]
    assert (r.level, r.category, r.reviewers, r.policy, r.state_dim) == ("L2", "grasp_failure", 2, "scripted", 92)
    assert r.characterize_prompt_hash == "c0ffee01" and r.certified is None
    assert read_manifest(out / MANIFEST_NAME) == rows
    card = (out / "README.md").read_text()
    assert "| libero_spatial | 0 | 2 | 0 | 0 | 2 |" in card
    assert "| grasp_failure | 2 |" in card and "reviewers: 2 distinct people" in card
    assert (out / "figures/scenes_by_suite_level.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    check = subprocess.run(["sha256sum", "-c", "--quiet", "SHA256SUMS"], cwd=out, capture_output=True, text=True)
    assert check.returncode == 0, check.stdout + check.stderr
    assert len((out / "SHA256SUMS").read_text().splitlines()) == 2 * 3 + 5  # + split.json, positions figure
    assert (out / "figures/object_positions.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # two scenes of one suite x level: the split keeps one of them for eval, and says so
    assert "eval" in {r.split for r in rows}
    split = json.loads((out / "split.json").read_text())
    assert (split["seed"], split["train_share"]) == (0, 0.19) and sum(split["counts"].values()) == 2
    assert "## Train / eval split" in card and "**eval** (" in card


def test_release_bytes_do_not_depend_on_where_or_when_it_was_built(run, tmp_path):
    build(release_config(run))
    elsewhere = tmp_path / "copied" / "somewhere" / "else"
    shutil.copytree(run, elsewhere, ignore=shutil.ignore_patterns("release"))
    build(release_config(elsewhere))
    first, second = run / "release", elsewhere / "release"
    assert (first / "SHA256SUMS").read_text() == (second / "SHA256SUMS").read_text()
    for line in (first / "SHA256SUMS").read_text().splitlines():
        rel = line.split("  ", 1)[1]
        assert (first / rel).read_bytes() == (second / rel).read_bytes(), rel
    assert str(tmp_path) not in (second / "README.md").read_text()


def test_release_sets_aside_an_annotation_without_localization(run):
    loc = next((run / "stage2" / "localizations").rglob("ep-b.json"))
    loc.unlink()
    rows = build(release_config(run))
    assert [r.episode_id for r in rows] == ["ep-a"]
    quarantine = (run / "release" / "_build" / "quarantine.jsonl").read_text().splitlines()
    assert len(quarantine) == 1 and '"reason":"no_localization"' in quarantine[0] and "ep-b.json" in quarantine[0]


def test_release_rebuild_removes_files_of_scenes_no_longer_released(run):
    rows = build(release_config(run))
    gone = run / "release" / rows[1].state_path
    assert gone.is_file()
    next((run / "stage3" / "annotations").rglob("episode_ep-b.json")).unlink()
    build(release_config(run))
    assert not gone.exists() and not gone.parent.exists()
    assert [r.episode_id for r in read_manifest(run / "release" / MANIFEST_NAME)] == ["ep-a"]


def test_release_never_includes_episodes_without_a_final_annotation(run):
    for f in (run / "stage3" / "annotations").rglob("*.json"):
        f.unlink()
    assert build(release_config(run)) == []
    assert not list((run / "release").glob("selected_bddl_scenes_*/**/*.npy"))


def test_two_generators_merge_into_one_release_that_verifies_and_rebuilds_identically(tmp_path, scene_source):
    from pipeline.errors import FatalError
    from pipeline.release.verify import verify_release

    good, bddl = npy_bytes(scene_source.failure), scene_source.bddl_text
    # the scripted expert at two noise levels, as two runs of one task selection
    a = make_run(tmp_path / "a", scene_source, {"scripted-i00-s0": (good, bddl)}, policy_params={"noise": 0.1})
    b = make_run(tmp_path / "b", scene_source, {"noisy-i00-s0": (good, bddl), "noisy-i00-s1": (good, bddl)},
                 policy="noisy", policy_params={"noise": 0.3})
    cfg = release_config(a, merge_runs=[str(b)])
    rows = build(cfg)
    gens = {r.episode_id: r.generator for r in rows}
    assert sorted(gens) == ["noisy-i00-s0", "noisy-i00-s1", "scripted-i00-s0"]
    assert gens["scripted-i00-s0"].startswith("scripted:scripted@") and gens["noisy-i00-s0"].startswith("scripted:noisy@")
    assert gens["noisy-i00-s0"] == gens["noisy-i00-s1"] != gens["scripted-i00-s0"]
    out = a / "release"
    card = (out / "README.md").read_text()
    assert f"| `{gens['noisy-i00-s0']}` | 2 |" in card and f"| `{gens['scripted-i00-s0']}` | 1 |" in card
    assert str(tmp_path) not in card  # the merged runs' folders are named, not located
    # the LeRobot rollouts and pre-failure histories take each run's own stage 1
    from pipeline.release.lerobot_export import history_episodes, rollout_episodes

    assert sorted(e.key.rsplit("/", 1)[1] for e in rollout_episodes(cfg)) == sorted(gens)
    assert {e.folder.parts[len(tmp_path.parts)] for e in history_episodes(cfg, out / "scenarios.parquet")} == {"a", "b"}
    reports, problems = verify_release(out, cfg.release)
    assert problems == [] and all(r.ok for r in reports), [p for r in reports for p in r.problems]
    sums = (out / "SHA256SUMS").read_bytes()
    shutil.rmtree(out)
    build(cfg)
    assert (out / "SHA256SUMS").read_bytes() == sums  # rebuilt byte for byte
    # the same episode key in two runs cannot both be released
    c = make_run(tmp_path / "c", scene_source, {"scripted-i00-s0": (good, bddl)})
    with pytest.raises(FatalError, match="in both"):
        build(release_config(a, merge_runs=[str(c)]))


def test_object_positions_are_read_from_the_scenes_states_and_libero_init_files(run):
    import numpy as np

    from pipeline.release.certify import scene_refs
    from pipeline.release.positions import collect
    from pipeline.sim import get_task

    cfg = release_config(run)
    rows = build(cfg)
    out = run / "release"
    [res] = collect(scene_refs(rows, out), cfg, out / "_build" / "positions")  # one task model; stored, not rebuilt
    init = get_task(rows[0].suite, rows[0].task).init_states()
    objects = len(res["official"]) // len(init)
    assert res["n_official"] == len(init) == 50 and res["n_scenes"] == 2 and objects >= 2
    assert len(res["scenes"]) == 2 * objects and res["note"] is None

    def at(state, xy):  # the pair sits at consecutive places of the flattened state (a free joint's x, y)
        return any(np.allclose(state[i:i + 2], xy, atol=1e-4) for i in range(1, len(state) - 1))

    state = np.load(out / rows[0].state_path)
    assert all(at(state, xy) for xy in res["scenes"][:objects])
    assert all(at(init[1], xy) for xy in res["official"][objects:2 * objects])
    assert res["official"][:objects] != res["official"][objects:2 * objects]  # init states differ in layout
