"""Recoverability certificate: the clean scripted expert from each scene, k tries."""

from __future__ import annotations

import pytest

import pipeline.release.certify as certify
from pipeline.release.build import build
from tests.release.factories import make_run, npy_bytes, release_config

pytestmark = pytest.mark.sim


@pytest.fixture()
def run(tmp_path, scene_source):
    return make_run(tmp_path / "run", scene_source, {"ep-a": (npy_bytes(scene_source.failure), scene_source.bddl_text)})


def test_a_scene_the_expert_recovers_is_certified_and_cached(run, monkeypatch):
    (row,) = build(release_config(run, certify_tries=2, certify_horizon=300))
    assert (row.certified, row.certify_successes, row.certify_tries) == (True, 1, 1)
    assert "Certified: 1 of 1 attempted" in (run / "release" / "README.md").read_text()
    # a rebuild reads the cached certificate instead of building an environment again
    monkeypatch.setattr(certify, "SimEnv", lambda *a, **k: pytest.fail("certificate was recomputed"))
    (again,) = build(release_config(run, certify_tries=2, certify_horizon=300))
    assert again == row


def test_a_scene_the_expert_cannot_finish_stays_released_but_uncertified(run):
    (row,) = build(release_config(run, certify_tries=2, certify_horizon=3))
    assert (row.certified, row.certify_successes, row.certify_tries) == (False, 0, 2)


def test_certify_tries_zero_skips_the_certificate(run):
    (row,) = build(release_config(run, certify_tries=0))
    assert (row.certified, row.certify_tries) == (None, 0)
