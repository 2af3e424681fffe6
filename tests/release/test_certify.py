"""Recoverability certificate: a zero-noise expert from each scene, k tries, and why it failed."""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest

import pipeline.release.certify as certify
from pipeline.release.build import build
from pipeline.release.reproduce import file_sums
from tests.release.factories import make_run, npy_bytes, release_config

pytestmark = pytest.mark.sim


@pytest.fixture()
def run(tmp_path, scene_source):
    return make_run(tmp_path / "run", scene_source, {"ep-a": (npy_bytes(scene_source.failure), scene_source.bddl_text)})


def test_a_scene_the_recovery_expert_recovers_is_certified_and_its_marker_is_the_cache(run, monkeypatch):
    cfg = release_config(run, "inline", certify_tries=2, certify_horizon=300)
    (row,) = build(cfg)
    assert (row.certified, row.certify_successes, row.certify_tries, row.certify_reason) == (True, 1, 1, None)
    card = (run / "release" / "README.md").read_text()
    assert "Certified: 1 of 1 attempted" in card and "The recovery expert" in card
    [marker] = (run / "release" / "_build" / "certificates" / "_done").iterdir()
    info = json.loads(marker.read_text())
    assert marker.name == f"{row.suite}__{row.task}__{row.episode_id}__step_{row.step:04d}.done"
    assert info["inputs"] == {"scene": f"{row.bddl_sha256[:16]}-{row.state_sha256[:16]}",
                              "expert": f"recovery{certify.EXPERT_VERSION['recovery']}",
                              "tries": 2, "horizon": 300, "chunk": 8}
    # a rebuild reads the marker instead of running the expert again ...
    monkeypatch.setattr(certify, "certify_one", lambda *a, **k: pytest.fail("certificate was recomputed"))
    (again,) = build(cfg)
    assert again == row
    # ... until something that changes a certificate changes (here the horizon)
    monkeypatch.undo()
    (shorter,) = build(release_config(run, "inline", certify_tries=2, certify_horizon=3))
    assert (shorter.certified, shorter.certify_reason) == (False, "timeout")
    assert json.loads(marker.read_text())["inputs"]["horizon"] == 3


def test_an_uncertified_scene_carries_the_reason_in_the_manifest_and_the_card(run):
    sums = None
    for _ in range(2):  # the reason is part of the released bytes: a rebuild reproduces them
        (row,) = build(release_config(run, certify_tries=2, certify_horizon=3))
        assert (row.certified, row.certify_successes, row.certify_tries) == (False, 0, 2)
        assert row.certify_reason == "timeout"  # 3 steps: still working when the horizon ran out
        assert sums is None or file_sums(run / "release") == sums
        sums = file_sums(run / "release")
    table = pq.read_table(run / "release" / "scenarios.parquet")
    assert table.schema.field("certify_reason").nullable and table.column("certify_reason").to_pylist() == ["timeout"]
    card = (run / "release" / "README.md").read_text()
    assert "| timeout | 1 |" in card and "| `libero_spatial/" in card and "| L2 | grasp_failure | timeout |" in card


def test_the_plain_expert_still_certifies_when_chosen(run):
    (row,) = build(release_config(run, certify_tries=1, certify_horizon=300, certify_expert="plain"))
    assert (row.certified, row.certify_reason) == (True, None)
    assert "The plain scripted expert" in (run / "release" / "README.md").read_text()


def test_certify_tries_zero_skips_the_certificate(run):
    (row,) = build(release_config(run, certify_tries=0))
    assert (row.certified, row.certify_tries, row.certify_reason) == (None, 0, None)


def test_an_expert_that_crashes_on_a_scene_leaves_it_uncertified_with_the_error(run, monkeypatch):
    class Broken:
        name, cameras, image_size = "broken", (), 64

        def reset(self, task, seed):
            pass

        def act(self, obs):
            raise RuntimeError("planner bug")

    monkeypatch.setattr(certify, "expert_factory", lambda kind, cfg: lambda env, seed, variation: Broken())
    (row,) = build(release_config(run, "inline", certify_tries=1, certify_horizon=50))
    assert (row.certified, row.certify_reason) == (False, "expert_error: RuntimeError: planner bug")
