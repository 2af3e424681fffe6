"""Property: on ANY string the parser returns a time inside the video or a Quarantine, never raises.

Bounded (`max_examples`, no deadline flakiness) so it runs in CI on every push.
"""

from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.labelers.vlm.parse import parse_characterization, parse_localization
from pipeline.records import Category, Level
from pipeline.labelers.vlm.schemas import CharacterizationAnswer, LocalizationAnswer, Quarantine

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

_json_scalar = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
)
_json_value = st.recursive(
    _json_scalar,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)
_answer_like = st.fixed_dictionaries(
    {"fail": st.one_of(st.floats(-5, 50), st.text(max_size=8), _json_value)},
    optional={"recovery_level": st.sampled_from(["L1", "l2", " L 3", "L9", ""]), "extra": _json_value},
)


@st.composite
def _mutated_answer(draw) -> str:
    """A plausible answer, then cut, spliced, duplicated or wrapped the way models garble JSON."""
    text = json.dumps(draw(_answer_like), allow_nan=True)
    if draw(st.booleans()):  # a repeated key, as some models write corrections inline
        text = text[:-1] + f', "fail": {draw(st.floats(-5, 50))}' + "}"
    ops = draw(st.lists(st.sampled_from(["cut", "insert", "delete", "nest", "think", "prose", "dup"]), max_size=4))
    for op in ops:
        i = draw(st.integers(0, len(text)))
        if op == "cut":
            text = text[:i]
        elif op == "insert":
            piece = draw(st.sampled_from(["{", "}", "[", '"', ",", ":", "0" * 50, "9" * 5000, "，", "“", "NaN"]))
            text = text[:i] + piece + text[i:]
        elif op == "delete":
            text = text[:i] + text[i + 1 :]
        elif op == "nest":
            n = draw(st.integers(1, 3000))  # past the decoder's recursion limit
            text = '{"answer": ' + "[" * n + text + "]" * draw(st.integers(0, n)) + "}"
        elif op == "think":
            text = draw(st.sampled_from(["<think>", "</think>", "<think>x</think>"])) + text
        elif op == "prose":
            text = "The robot fails at " + text + " seconds."
        elif op == "dup":
            text = text + " " + text
    return text


def _within_video_or_quarantine(out, duration: float) -> None:
    if isinstance(out, Quarantine):
        assert out.reason is not None
        return
    assert isinstance(out, LocalizationAnswer)
    assert 0.0 <= out.fail <= duration


@SETTINGS
@given(raw=st.text(max_size=400), duration=st.floats(0.1, 120.0))
def test_any_text_gives_a_time_inside_the_video_or_a_quarantine(raw: str, duration: float):
    _within_video_or_quarantine(parse_localization(raw, duration), duration)


@SETTINGS
@given(raw=_mutated_answer(), duration=st.floats(0.1, 120.0))
def test_mutated_answers_give_a_time_inside_the_video_or_a_quarantine(raw: str, duration: float):
    _within_video_or_quarantine(parse_localization(raw, duration), duration)


@SETTINGS
@given(raw=st.one_of(st.text(max_size=400), _mutated_answer()))
def test_characterization_never_raises(raw: str):
    assert isinstance(parse_characterization(raw), CharacterizationAnswer | Quarantine)


_reasoning = st.text(st.characters(blacklist_characters="{}<>", blacklist_categories=("Cs",)), max_size=80)
_characterization = st.builds(
    CharacterizationAnswer,
    recovery_level=st.sampled_from(list(Level)),
    failure_category=st.sampled_from(list(Category)),
    recovery_action=st.text(st.characters(blacklist_categories=("Cs", "Cc", "Zs", "Zl", "Zp")), min_size=1, max_size=40),
)


@st.composite
def _answer_as_a_version_writes_it(draw, obj: dict) -> str:
    """v2 prompts ask for the JSON object only (reasoning, if any, in the model's reasoning
    channel, which reaches us as a closed think block); v1 let prose precede the JSON."""
    answer = json.dumps(obj, ensure_ascii=draw(st.booleans()))
    if draw(st.sampled_from(["v1", "v2"])) == "v1":
        return draw(_reasoning) + "\n" + answer
    return (f"<think>{draw(_reasoning)}</think>" if draw(st.booleans()) else "") + answer


@SETTINGS
@given(data=st.data(), tenths=st.integers(0, 1200), extra=st.integers(0, 50))
def test_a_valid_answer_of_either_prompt_version_parses_to_itself(data, tenths: int, extra: int):
    duration = (tenths + extra) / 10
    raw = data.draw(_answer_as_a_version_writes_it({"fail": tenths / 10}))
    assert parse_localization(raw, duration) == LocalizationAnswer(fail=tenths / 10)
    char = data.draw(_characterization)
    raw = data.draw(_answer_as_a_version_writes_it(char.model_dump(mode="json")))
    assert parse_characterization(raw) == char
