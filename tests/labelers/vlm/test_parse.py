"""The loss-free parser against a corpus of realistic bad (and good) model outputs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.records import Category, Level
from pipeline.labelers.vlm.backends.base import VLMResult
from pipeline.labelers.vlm.parse import answer_text, find_json_objects, parse_characterization, parse_localization
from pipeline.labelers.vlm.schemas import CharacterizationAnswer, LocalizationAnswer, Quarantine, QuarantineReason

DATA = Path(__file__).parent / "data"


def _corpus(name: str) -> list[dict]:
    return [json.loads(line) for line in (DATA / name).read_text(encoding="utf-8").splitlines() if line.strip()]


LOC = _corpus("localization_corpus.jsonl")
CHAR = _corpus("characterization_corpus.jsonl")


def _input(case: dict, task: str) -> VLMResult | str:
    if "raw" in case:
        return case["raw"]
    return VLMResult(backend="openai", model="m", task=task, prompt_name="p", prompt_hash="h", **case["result"])


def test_corpus_has_at_least_thirty_bad_outputs():
    bad = [c for c in LOC + CHAR if "quarantine" in c["expect"] or "raw" in c and c["raw"].strip() != c["raw"]]
    assert len(LOC) >= 30 and len(bad) >= 30
    assert {c["expect"]["quarantine"] for c in LOC if "quarantine" in c["expect"]} >= {
        "empty",
        "truncated",
        "no_json",
        "schema",
        "out_of_range",
        "ambiguous",
        "backend_error",
    }


@pytest.mark.parametrize("case", LOC, ids=[c["id"] for c in LOC])
def test_localization_corpus_case_gives_expected_outcome(case):
    got = parse_localization(_input(case, "localize"), case["duration_s"])
    if "quarantine" in case["expect"]:
        assert isinstance(got, Quarantine), got
        assert got.reason == QuarantineReason(case["expect"]["quarantine"]), got.detail
        assert got.raw_text is not None or case["id"] in ("empty_output", "backend_error")
        assert got.detail
    else:
        assert isinstance(got, LocalizationAnswer), got
        assert got.fail == pytest.approx(case["expect"]["fail"], abs=1e-9)


@pytest.mark.parametrize("case", CHAR, ids=[c["id"] for c in CHAR])
def test_characterization_corpus_case_gives_expected_outcome(case):
    got = parse_characterization(_input(case, "characterize"))
    if "quarantine" in case["expect"]:
        assert isinstance(got, Quarantine), got
        assert got.reason == QuarantineReason(case["expect"]["quarantine"]), got.detail
    else:
        assert isinstance(got, CharacterizationAnswer), got
        assert got.recovery_level == Level(case["expect"]["recovery_level"])
        assert got.failure_category == Category(case["expect"]["failure_category"])
        assert got.recovery_action == case["expect"]["recovery_action"]


def test_quarantine_keeps_the_whole_raw_text_including_thinking():
    result = VLMResult(
        backend="openai",
        model="m",
        task="localize",
        prompt_name="p",
        prompt_hash="h",
        content=None,
        reasoning="long thinking about 3.0 s",
        finish_reason="length",
    )
    got = parse_localization(result, 10.0)
    assert isinstance(got, Quarantine)
    assert "long thinking about 3.0 s" in got.raw_text


def test_schema_detail_names_the_bad_field():
    got = parse_characterization('{"recovery_level": "L5", "failure_category": "other", "recovery_action": "x"}')
    assert isinstance(got, Quarantine) and "recovery_level" in got.detail and "L5" in got.detail


def test_out_of_range_detail_states_time_and_duration():
    got = parse_localization('{"fail": 31.0}', 26.0)
    assert isinstance(got, Quarantine) and "31.0" in got.detail and "26.00" in got.detail


def test_answer_text_takes_text_after_the_last_marker():
    text, problem = answer_text("<think>x</think>A</think>B")
    assert problem is None and text == "B"


def test_find_json_objects_skips_braces_inside_strings():
    assert find_json_objects('x {"a": "}{", "b": 1} y') == [{"a": "}{", "b": 1}]


# -- bounds (issue 12): the three strings that raised or silently chose on the landed parser


def test_a_five_thousand_digit_number_is_quarantined_not_raised():
    out = parse_localization('{"fail": 1' + "0" * 5000 + "}", 10.0)
    assert isinstance(out, Quarantine) and out.reason is QuarantineReason.schema


def test_five_thousand_nested_brackets_are_quarantined_not_raised():
    out = parse_localization('{"fail": ' + "[" * 5000, 10.0)
    assert isinstance(out, Quarantine) and out.reason is QuarantineReason.no_json


def test_a_key_repeated_with_different_values_is_ambiguous():
    out = parse_localization('{"fail": 2.0, "fail": 9.0}', 10.0)
    assert isinstance(out, Quarantine) and out.reason is QuarantineReason.ambiguous
    assert "'fail'" in out.detail and "2.0" in out.detail and "9.0" in out.detail


def test_a_key_repeated_with_the_same_value_is_harmless():
    assert parse_localization('{"fail": 2.0, "fail": 2.0}', 10.0) == LocalizationAnswer(fail=2.0)


def test_a_repeated_key_in_a_characterization_is_ambiguous():
    raw = ('{"recovery_level": "L1", "recovery_level": "L3", '
           '"failure_category": "grasp_failure", "recovery_action": "x"}')
    out = parse_characterization(raw)
    assert isinstance(out, Quarantine) and out.reason is QuarantineReason.ambiguous


def test_an_oversized_answer_is_quarantined_without_scanning():
    out = parse_localization('{"fail": 2.0}' + " " * 30_000 + "x", 10.0)
    assert isinstance(out, Quarantine) and out.reason is QuarantineReason.schema
    assert "characters" in out.detail
