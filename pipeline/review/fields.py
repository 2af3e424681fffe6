"""The four reviewed fields, their validation, and per-field agreement between reviewers.

Inputs: a proposal (the model's values, possibly incomplete for quarantined items), a
reviewer's edits, or K reviewers' resolved values.
Outputs: complete, validated values; or (agreed values, disputed field names).
Invariants: a value that fails validation raises `FieldError` naming the field; the
failure time and step always agree (`fail_step = round(fail_time_s * control_hz)`).
Agreement: level and category must be equal; failure times within ±tolerance of each
other (max - min <= tolerance); actions when the texts are the same (ignoring case,
surrounding spaces and a final full stop). A flag (values None) disputes every field.
"""

from __future__ import annotations

import statistics

from pipeline.records import Category, Level, step_at_time

FIELDS = ("fail_time_s", "recovery_level", "failure_category", "recovery_action")
LEVELS = [lv.value for lv in Level]
CATEGORIES = [c.value for c in Category]
ACTION_MAX = 200


class FieldError(ValueError):
    def __init__(self, field: str, message: str):
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message


def validate_field(field: str, value, duration_s: float | None) -> object:
    """Check one field's value; return it normalized, or raise FieldError naming the field."""
    if field == "recovery_level":
        if value not in LEVELS:
            raise FieldError(field, f"must be one of {LEVELS}, got {value!r}")
        return value
    if field == "failure_category":
        if value not in CATEGORIES:
            raise FieldError(field, f"must be one of {CATEGORIES}, got {value!r}")
        return value
    if field == "recovery_action":
        if not isinstance(value, str) or not value.strip():
            raise FieldError(field, "must be a non-empty imperative sentence")
        value = " ".join(value.split())
        if len(value) > ACTION_MAX:
            raise FieldError(field, f"must be at most {ACTION_MAX} characters, got {len(value)}")
        return value
    if field == "fail_time_s":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise FieldError(field, f"must be a number of seconds, got {value!r}")
        if value != value or value < 0 or (duration_s is not None and value > duration_s + 1e-6):
            limit = f"[0, {duration_s:.2f}]" if duration_s is not None else ">= 0"
            raise FieldError(field, f"must be within the episode, {limit} s, got {value}")
        return round(float(value), 3)
    raise FieldError(field, f"is not a reviewable field; choose from {list(FIELDS)}")


def resolve(proposal: dict, edits: dict, duration_s: float | None, control_hz: int) -> dict:
    """The proposal overlaid with validated edits; every field must end up with a value."""
    unknown = [f for f in edits if f not in FIELDS]
    if unknown:
        raise FieldError(unknown[0], f"is not a reviewable field; choose from {list(FIELDS)}")
    out = {}
    for field in FIELDS:
        if field in edits:
            out[field] = validate_field(field, edits[field], duration_s)
        elif proposal.get(field) is None:
            raise FieldError(field, "the model proposed no value; give one (revise)")
        else:
            out[field] = proposal[field]
    out["fail_step"] = step_at_time(out["fail_time_s"], control_hz)
    return out


def same_action(a: str, b: str) -> bool:
    def norm(s: str) -> str:
        return " ".join(s.split()).rstrip(".").casefold()

    return norm(a) == norm(b)


def agreement(values: list[dict | None], tolerance_s: float, control_hz: int) -> tuple[dict, list[str]]:
    """Per-field agreement of K reviewers' resolved values -> (agreed values, disputed fields)."""
    if not values or any(v is None for v in values):
        return {}, list(FIELDS)
    agreed: dict = {}
    disputed: list[str] = []
    times = [v["fail_time_s"] for v in values]
    if max(times) - min(times) <= tolerance_s + 1e-9:
        # the reviewers' common time: their mean, reported on the control grid
        t = round(statistics.fmean(times), 3)
        agreed["fail_time_s"], agreed["fail_step"] = t, step_at_time(t, control_hz)
    else:
        disputed.append("fail_time_s")
    for field in ("recovery_level", "failure_category"):
        if len({v[field] for v in values}) == 1:
            agreed[field] = values[0][field]
        else:
            disputed.append(field)
    first = values[0]["recovery_action"]
    if all(same_action(first, v["recovery_action"]) for v in values[1:]):
        agreed["recovery_action"] = first
    else:
        disputed.append("recovery_action")
    return agreed, disputed
