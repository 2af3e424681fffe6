"""Loss-free parsing of VLM answers: an answer, or a Quarantine that keeps the raw text.

Input: a `VLMResult` (or a bare string, treated as complete raw output) and, for
localization, the video duration. Output: `LocalizationAnswer | Quarantine` /
`CharacterizationAnswer | Quarantine`. Nothing raises on bad model output.

Steps, in order:
1. `finish_reason == "length"` -> `truncated`; the thinking is never mined for an answer.
2. Keep the text after the LAST reasoning end marker (`</think>`, ...). A start marker with
   no end marker means the thinking never closed -> `truncated`. Nothing left -> `empty`.
3. Strict JSON: every JSON object in the text, found by trying a real JSON decoder at each
   `{` (a strict-JSON answer is the first; braces inside strings are handled); else the scan
   after conservative repairs (full-width punctuation and curly quotes, trailing commas,
   unquoted keys, single quotes when the text has no double quotes). None -> `no_json`.
4. Validate every object found. Valid answers that all agree -> the answer; valid answers
   that disagree -> `ambiguous`; no valid one -> the first object's problem (`schema`, or
   `out_of_range` for a time outside the video).

Bounds (the parser never raises on any string, issue 12):
- Answer text longer than `MAX_ANSWER_CHARS` is `schema` without being scanned; JSON nested
  deeper than `MAX_DEPTH` is not decoded; an integer of more than `_MAX_INT_DIGITS` digits
  becomes infinity (then `schema`) instead of hitting Python's int-conversion limit.
- A key repeated with different values in one object (`{"fail": 2.0, "fail": 9.0}`) is
  `ambiguous`: JSON decoders keep the last one silently, and which one the model meant is
  unknowable. A key repeated with the same value is harmless.

Decisions (the issue was silent):
- More than one decimal is ROUNDED half-up to 0.1 s, not rejected: the raw text keeps the
  original, and rejecting would quarantine answers whose meaning is clear.
- A time up to 0.05 s past the duration (rounding) is clamped to the last 0.1 s inside the
  video; anything further, or negative, is `out_of_range`.
- A number written as a string ("2.0", "2.0s", "2.0秒") is accepted; "00:02", "two", null,
  booleans, lists, NaN and infinities are `schema`.
- Level accepts "L2" in any case/spacing; category accepts case, spaces and hyphens
  ("Grasp Failure"); an empty or over-long action is `schema`. Extra keys are ignored.
"""

from __future__ import annotations

import json
import math
import re
import unicodedata
from collections.abc import Callable
from decimal import ROUND_FLOOR, ROUND_HALF_UP, Decimal

from pipeline.records import Category, Level
from pipeline.labelers.vlm.backends.base import VLMResult
from pipeline.labelers.vlm.schemas import (
    ACTION_MAX_CHARS,
    CharacterizationAnswer,
    LocalizationAnswer,
    Quarantine,
    QuarantineReason,
)

END_MARKERS = ("</think>", "</thinking>", "</reasoning>", "<|end_of_thought|>")
START_MARKERS = ("<think>", "<thinking>", "<reasoning>", "<|begin_of_thought|>")
RANGE_SLACK_S = 0.05  # half the answer resolution
_MAX_OBJECT_STARTS = 500  # bound the scan on pathological outputs
MAX_ANSWER_CHARS = 20_000  # a real answer is under 1 kB; the thinking is cut off before this
MAX_DEPTH = 32  # real answers nest 1-2 levels; Python's decoder recurses per level
_MAX_INT_DIGITS = 400  # far below Python's 4300-digit int-conversion limit
_QUOTES = str.maketrans({"“": '"', "”": '"', "„": '"', "‘": "'", "’": "'", "「": '"', "」": '"'})
_NUMBER_STR = re.compile(r"^\s*([+-]?\d+(?:\.\d+)?)\s*(?:s|sec|secs|seconds?|秒)?\s*$", re.IGNORECASE)

Answer = LocalizationAnswer | CharacterizationAnswer
Validated = tuple[Answer | None, QuarantineReason | None, str]


class _Problem(ValueError):
    def __init__(self, reason: QuarantineReason, detail: str):
        super().__init__(detail)
        self.reason = reason


def answer_text(raw: str) -> tuple[str | None, Quarantine | None]:
    """The part of `raw` after the final reasoning end marker, or why there is none."""
    cut = max((raw.rfind(m) + len(m) for m in END_MARKERS if m in raw), default=-1)
    if cut >= 0:
        text = raw[cut:]
    elif _thinking_opened(raw):
        return None, Quarantine(reason=QuarantineReason.truncated, detail="thinking never closed", raw_text=raw)
    else:
        text = raw
    if not text.strip():
        return None, Quarantine(reason=QuarantineReason.empty, detail="no answer text", raw_text=raw)
    return text.strip(), None


def _thinking_opened(raw: str) -> bool:
    """A reasoning start marker before any JSON object began: thinking that was cut off. One
    after the first `{` is text inside the answer (an action that names a tag), not thinking."""
    starts = [raw.find(m) for m in START_MARKERS if m in raw]
    brace = raw.find("{")
    return bool(starts) and (brace < 0 or min(starts) < brace)


class _DuplicateKey(ValueError):
    pass


def _no_conflicting_keys(pairs: list[tuple[str, object]]) -> dict:
    obj: dict = {}
    for key, value in pairs:
        if key in obj and obj[key] != value:
            shown = f"{json.dumps(obj[key], ensure_ascii=False)} and {json.dumps(value, ensure_ascii=False)}"
            raise _DuplicateKey(f"key {key!r} given twice with different values ({shown[:200]})")
        obj[key] = value
    return obj


def _int(digits: str) -> int | float:
    return int(digits) if len(digits) <= _MAX_INT_DIGITS else float(digits)  # float: inf, never raises


def max_nesting(text: str) -> int:
    """Deepest bracket nesting in `text`, counting brackets inside strings too (an upper bound)."""
    depth = deepest = 0
    for ch in text:
        if ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(depth - 1, 0)
    return deepest


def find_json_objects(text: str, duplicates: list[str] | None = None) -> list[dict]:
    """Every top-level-or-nested JSON object in `text`, in order of its opening brace.

    Objects that repeat a key with different values are not returned; their description is
    appended to `duplicates` when given.
    """
    if max_nesting(text) > MAX_DEPTH:
        return []  # callers report no_json; deep nesting is never a real answer
    decoder = json.JSONDecoder(
        # NaN / Infinity decode to float so validation can name the problem
        parse_constant=lambda c: float(c.replace("Infinity", "inf")),
        parse_int=_int,
        object_pairs_hook=_no_conflicting_keys,
    )
    found: list[dict] = []
    start = text.find("{")
    tries = 0
    while start != -1 and tries < _MAX_OBJECT_STARTS:
        tries += 1
        try:
            obj, _ = decoder.raw_decode(text, start)
            if isinstance(obj, dict):
                found.append(obj)
        except _DuplicateKey as dup:
            if duplicates is not None and str(dup) not in duplicates:
                duplicates.append(str(dup))
        except (json.JSONDecodeError, RecursionError, ValueError):
            pass  # not JSON at this brace; the bounds above keep RecursionError theoretical
        start = text.find("{", start + 1)
    return found


def repair(text: str) -> str:
    """Conservative fixes for near-JSON; used only when the text as written yields no answer."""
    t = unicodedata.normalize("NFKC", text).translate(_QUOTES)  # ｛“fail”：２.０｝ -> {"fail":2.0}
    t = re.sub(r",\s*([}\]])", r"\1", t)  # trailing commas
    t = re.sub(r"([{,]\s*)([A-Za-z_][A-Za-z0-9_]*)\s*:", r'\1"\2":', t)  # unquoted keys
    if '"' not in t:
        t = t.replace("'", '"')  # Python-style dicts
    return t


def _number(value: object, key: str) -> float:
    if isinstance(value, bool) or value is None:
        raise _Problem(QuarantineReason.schema, f"{key!r} must be a number, got {json.dumps(value)}")
    if isinstance(value, str):
        m = _NUMBER_STR.match(value)
        if not m:
            raise _Problem(QuarantineReason.schema, f"{key!r} must be a number of seconds, got string {value!r}")
        value = float(m.group(1))
    if not isinstance(value, (int, float)):
        raise _Problem(QuarantineReason.schema, f"{key!r} must be a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise _Problem(QuarantineReason.schema, f"{key!r} must be finite, got {value}")
    return float(value)


def _tenths(value: float, rounding: str) -> float:
    return float(Decimal(repr(value)).quantize(Decimal("0.1"), rounding=rounding))


def validate_localization(obj: dict, duration_s: float) -> LocalizationAnswer:
    if "fail" not in obj:
        raise _Problem(QuarantineReason.schema, f"missing key 'fail' (keys: {sorted(obj)})")
    t = _number(obj["fail"], "fail")
    if t < 0 or t > duration_s + RANGE_SLACK_S:
        raise _Problem(QuarantineReason.out_of_range, f"fail={t} s outside the video [0, {duration_s:.2f}] s")
    return LocalizationAnswer(fail=min(_tenths(t, ROUND_HALF_UP), _tenths(duration_s, ROUND_FLOOR)))


def validate_characterization(obj: dict) -> CharacterizationAnswer:
    missing = [k for k in ("recovery_level", "failure_category", "recovery_action") if k not in obj]
    if missing:
        raise _Problem(QuarantineReason.schema, f"missing key(s) {missing} (keys: {sorted(obj)})")
    level, category, action = obj["recovery_level"], obj["failure_category"], obj["recovery_action"]
    if not isinstance(level, str) or re.sub(r"\s+", "", level).upper() not in Level.__members__:
        raise _Problem(
            QuarantineReason.schema,
            f"'recovery_level' must be one of L1..L4, got {json.dumps(level, ensure_ascii=False)}",
        )
    cat = re.sub(r"[\s\-]+", "_", category.strip().lower()) if isinstance(category, str) else None
    if cat not in Category.__members__:
        raise _Problem(
            QuarantineReason.schema,
            f"'failure_category' must be one of {[c.value for c in Category]}, "
            f"got {json.dumps(category, ensure_ascii=False)}",
        )
    if not isinstance(action, str) or not action.strip():
        raise _Problem(QuarantineReason.schema, "'recovery_action' must be a non-empty string")
    if len(action.strip()) > ACTION_MAX_CHARS:
        raise _Problem(QuarantineReason.schema, f"'recovery_action' longer than {ACTION_MAX_CHARS} characters")
    return CharacterizationAnswer(
        recovery_level=Level(re.sub(r"\s+", "", level).upper()),
        failure_category=Category(cat),
        recovery_action=action.strip(),
    )


def _decide(text: str, check: Callable[[dict], Answer]) -> Validated:
    duplicates: list[str] = []
    objects = find_json_objects(text, duplicates)
    if duplicates:
        return None, QuarantineReason.ambiguous, "; ".join(duplicates[:3])
    answers: list[Answer] = []
    first_problem: _Problem | None = None
    for obj in objects:
        try:
            answers.append(check(obj))
        except _Problem as p:
            first_problem = first_problem or p
    if answers:
        distinct = list(dict.fromkeys(answers))
        if len(distinct) > 1:
            shown = "; ".join(a.model_dump_json() for a in distinct[:4])
            return None, QuarantineReason.ambiguous, f"{len(distinct)} different valid answers: {shown}"
        return answers[0], None, ""
    if first_problem:
        return None, first_problem.reason, str(first_problem)
    return None, QuarantineReason.no_json, "no JSON object found"


def _parse(result: VLMResult | str, check: Callable[[dict], Answer]) -> Answer | Quarantine:
    if isinstance(result, str):
        raw, finish, error = result, None, None
    else:
        raw, finish, error = result.raw_text, result.finish_reason, result.error
    if error:
        return Quarantine(reason=QuarantineReason.backend_error, detail=error, raw_text=raw or None)
    if finish == "length":
        return Quarantine(reason=QuarantineReason.truncated, detail="generation hit the token limit", raw_text=raw)
    if isinstance(result, VLMResult) and result.reasoning and not (result.content or "").strip():
        return Quarantine(reason=QuarantineReason.empty, detail="thinking but no answer content", raw_text=raw)
    text, problem = answer_text(raw)
    if problem:
        return problem
    if len(text) > MAX_ANSWER_CHARS:
        detail = f"answer text is {len(text)} characters, more than {MAX_ANSWER_CHARS}"
        return Quarantine(reason=QuarantineReason.schema, detail=detail, raw_text=raw)
    # the scan's first object is the whole text when the text is strict JSON; nested and
    # later objects follow, so `{"answer": {"fail": 4.0}}` still yields the inner answer
    verdict = _decide(text, check)
    if verdict[0] is None:
        repaired = repair(text)
        if repaired != text:
            second = _decide(repaired, check)
            if second[0] is not None or verdict[1] is QuarantineReason.no_json:
                verdict = second
    answer, reason, detail = verdict
    if answer is not None:
        return answer
    if reason is QuarantineReason.no_json and "{" in text:
        detail = "unterminated or malformed JSON object"
    return Quarantine(reason=reason, detail=detail, raw_text=raw)


def parse_localization(result: VLMResult | str, duration_s: float) -> LocalizationAnswer | Quarantine:
    """`{"fail": t}` with 0 <= t <= duration_s (one decimal), or the reason it is unusable."""
    return _parse(result, lambda obj: validate_localization(obj, duration_s))


def parse_characterization(result: VLMResult | str) -> CharacterizationAnswer | Quarantine:
    """Level, category and action, or the reason they are unusable."""
    return _parse(result, validate_characterization)
