"""The labeler protocols and their typed answers: both families behind one interface, the
stored VLM answer as a model (same JSON as before), one result per input or a named error."""

from __future__ import annotations

import json

import pytest

from pipeline.config import VLMConfig
from pipeline.errors import FatalError
from pipeline.labelers.base import Characterizer, Episode, Localizer, Onset, Provenance
from pipeline.labelers.registry import make_characterizer, make_localizer
from pipeline.labelers.vlm.backends.base import VLMResult
from pipeline.labelers.vlm.labeler import VLMCharacterizer, VLMLocalizer, onset_of
from pipeline.records import EpisodeRecord, Localization
from tests.labelers.vlm.loopback_server import LoopbackServer
from tests.review.sample_run import SUITE, TASK, build

PROVENANCE_KEYS = ["source", "model", "prompt_name", "prompt_hash", "raw_text", "latency_s"]


def _result(**kw) -> VLMResult:
    return VLMResult(backend="openai", model="Qwen/Qwen3.5-27B", task="localize", prompt_name="localize.v1.zh",
                     prompt_hash="ab" * 32, latency_s=1.25, **kw)


def _record(ep: str, steps: int = 60) -> EpisodeRecord:
    return EpisodeRecord(suite=SUITE, task=TASK, task_index=0, instruction="put the bowl on the plate", episode_id=ep,
                         init_state=0, policy="scripted", policy_kind="scripted", seed=0, chunk_size=1, horizon=steps,
                         settle_steps=0, steps=steps, success=False, wall_time_s=1.0, state_dim=9,
                         path=f"episodes/{SUITE}/{TASK}/{ep}", videos={"agentview": "video_agentview.mp4"})


def _openai(base_url: str, scenario: str = "ok") -> VLMConfig:
    return VLMConfig.model_validate({"backend": "openai", "openai": {"base_url": base_url, "model": scenario,
                                                                     "max_retries": 0}})


def test_provenance_keeps_thinking_and_answer_together():
    p = Provenance.of(_result(content='{"fail": 1.0}', reasoning="why"))
    assert p.raw_text == '<think>\nwhy\n</think>\n{"fail": 1.0}' and p.prompt_hash == "ab" * 32
    q = p.quarantine("s/t/e", "stage2", "no_json", "nothing")
    assert (q.source, q.model, q.raw_text, q.reason) == ("openai", "Qwen/Qwen3.5-27B", p.raw_text, "no_json")


def test_the_stored_vlm_answer_keeps_the_fields_and_order_the_vlm_step_always_wrote(tmp_path):
    ep = Episode(_record("e"), tmp_path)
    ok = onset_of(_result(content='{"fail": 1.0}'), ep)
    assert list(ok.stored()) == [*PROVENANCE_KEYS, "fail_time_s"] and ok.stored()["fail_time_s"] == 1.0
    cut = onset_of(_result(reasoning="thinking about 2.0 s", finish_reason="length"), ep)
    assert list(cut.stored()) == [*PROVENANCE_KEYS, "reason", "detail"] and cut.reason == "truncated"
    assert "thinking about 2.0 s" in cut.raw_text
    failed = onset_of(_result(error="HTTP 500"), ep)
    assert (failed.reason, failed.detail) == ("backend_error", "HTTP 500")
    no_video = Onset(source="openai", reason="no_video", detail="no agentview video in x")
    assert list(no_video.stored()) == ["source", "reason", "detail"]
    for onset in (ok, cut, failed, no_video):  # what the episode worker reads back
        assert Onset.model_validate_json(json.dumps(onset.stored())) == onset


def test_the_registry_builds_both_families_behind_the_protocols(tmp_path):
    simstate = VLMConfig(backend="simstate")
    assert isinstance(make_localizer(simstate), Localizer)
    assert isinstance(make_characterizer(simstate, tmp_path), Characterizer)
    with LoopbackServer() as srv:
        localizer, characterizer = make_localizer(_openai(srv.base_url)), make_characterizer(_openai(srv.base_url), tmp_path)
        assert isinstance(localizer, Localizer) and isinstance(characterizer, Characterizer)
        assert localizer.name == characterizer.name == "openai"
        localizer.close()
        characterizer.close()


def test_the_vlm_localizer_answers_every_episode_in_order_a_missing_video_included(tmp_path):
    build(tmp_path, n_episodes=2, n_quarantined=0, wrist=False)
    eps = [Episode(_record(f"scripted-i{i:02d}-s0"), tmp_path / "stage1" / "episodes" / SUITE / TASK /
                   f"scripted-i{i:02d}-s0") for i in range(2)]
    eps = [Episode(eps[0].record, eps[0].folder, eps[0].folder / "video_agentview.mp4"), eps[1]]  # 2nd: no video
    ticks = []
    with LoopbackServer(answer='{"fail": 1.5}') as srv:
        localizer = VLMLocalizer(_openai(srv.base_url))
        try:
            got = localizer.localize(eps, progress=lambda: ticks.append(1))
        finally:
            localizer.close()
    assert [o.fail_time_s for o in got] == [1.5, None] and got[1].reason == "no_video"
    assert got[0].model == "ok" and got[0].prompt_name.startswith("localize.") and ticks == [1]


class _Lossy:
    """A real backend that drops the last result of every batch (a bug a backend could have)."""

    def __init__(self, inner):
        self.inner, self.name = inner, inner.name

    def run(self, requests, progress=None):
        return self.inner.run(requests, progress)[:-1]

    def close(self):
        self.inner.close()


def test_a_backend_that_loses_a_result_stops_the_run_instead_of_shifting_answers(tmp_path):
    from pipeline.labelers.vlm.backends import make_backend

    build(tmp_path, n_episodes=2, n_quarantined=0, wrist=False)
    locs = [Localization.model_validate_json(p.read_text())
            for p in sorted((tmp_path / "stage2" / "localizations").rglob("*.json"))]
    with LoopbackServer(answer=json.dumps({"recovery_level": "L1", "failure_category": "grasp_failure",
                                           "recovery_action": "Grasp the bowl again"})) as srv:
        cfg = _openai(srv.base_url)
        characterizer = VLMCharacterizer(cfg, tmp_path, backend=_Lossy(make_backend(cfg)))
        try:
            with pytest.raises(FatalError, match="1 results for 2 requests"):
                characterizer.characterize(locs)
        finally:
            characterizer.close()
