"""The four reviewed fields, their validation, and per-field agreement between reviewers.

Inputs: a proposal (the model's values, possibly incomplete for quarantined items), a
reviewer's edits, or K reviewers' resolved values.
Outputs: complete, validated values; or (agreed values, disputed field names).
Invariants: a value that fails validation raises `FieldError` naming the field; failure
times live on the control grid (1/control_hz, 0.05 s at 20 Hz): a time between two steps is
snapped to the nearest one (half-way goes to the later step), so the failure time and step
always agree (`fail_time_s == fail_step / control_hz`).
Agreement: level and category must be equal; failure times within ±tolerance of each
other (max - min <= tolerance); actions when the texts are the same (ignoring case,
surrounding spaces and a final full stop). A flag (values None) disputes every field.
The agreed time is the median of the reviewers' control steps; with an even K whose middle
two steps have no step half-way between them, the earlier of the two nearest steps is taken
(deterministic, and on the grid: never a mean such as 3.075 s).
"""

from __future__ import annotations

import math

from pipeline.records import Category, Level

FIELDS = ("fail_time_s", "recovery_level", "failure_category", "recovery_action")
LEVELS = [lv.value for lv in Level]
CATEGORIES = [c.value for c in Category]
ACTION_MAX = 200


class FieldError(ValueError):
    def __init__(self, field: str, message: str):
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message


def snap_step(time_s: float, control_hz: int) -> int:
    """The control step nearest to `time_s` (half-way rounds up, whatever the float noise)."""
    return math.floor(time_s * control_hz + 0.5 + 1e-9)


def grid_time(step: int, control_hz: int) -> float:
    """The time of a control step, written as the grid shows it (59 -> 2.95 at 20 Hz)."""
    return round(step / control_hz, 6)


def validate_field(field: str, value, duration_s: float | None, control_hz: int = 20) -> object:
    """Check one field's value; return it normalized, or raise FieldError naming the field.

    A failure time is snapped to the control grid (see the module docstring)."""
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
        step = snap_step(float(value), control_hz)
        if duration_s is not None and step / control_hz > duration_s + 1e-6:
            step = math.floor(duration_s * control_hz + 1e-9)  # the last step inside the episode
        return grid_time(step, control_hz)
    raise FieldError(field, f"is not a reviewable field; choose from {list(FIELDS)}")


def resolve(proposal: dict, edits: dict, duration_s: float | None, control_hz: int) -> dict:
    """The proposal overlaid with validated edits; every field must end up with a value."""
    unknown = [f for f in edits if f not in FIELDS]
    if unknown:
        raise FieldError(unknown[0], f"is not a reviewable field; choose from {list(FIELDS)}")
    out = {}
    for field in FIELDS:
        if field in edits:
            out[field] = validate_field(field, edits[field], duration_s, control_hz)
        elif proposal.get(field) is None:
            raise FieldError(field, "the model proposed no value; give one (revise)")
        elif field == "fail_time_s":  # the model's time, on the same grid as the reviewers'
            out[field] = grid_time(snap_step(float(proposal[field]), control_hz), control_hz)
        else:
            out[field] = proposal[field]
    out["fail_step"] = snap_step(out["fail_time_s"], control_hz)
    return out


def edited_fields(proposal: dict, values: dict, control_hz: int) -> list[str]:
    """The fields whose resolved value differs from the model's (normalized) proposal.

    Setting the model's own value (its time on the grid, its action up to case, spaces and
    a final full stop) is not an edit."""
    out = []
    for field in FIELDS:
        mine, model = values.get(field), proposal.get(field)
        if model is None:
            same = False
        elif field == "fail_time_s":
            same = snap_step(float(mine), control_hz) == snap_step(float(model), control_hz)
        elif field == "recovery_action":
            same = same_action(mine, model)
        else:
            same = mine == model
        if not same:
            out.append(field)
    return out


def same_action(a: str, b: str) -> bool:
    def norm(s: str) -> str:
        return " ".join(s.split()).rstrip(".").casefold()

    return norm(a) == norm(b)


def agreed_step(steps: list[int]) -> int:
    """The median control step; half-way between two steps (even K) goes to the earlier one."""
    ordered = sorted(steps)
    mid = len(ordered) // 2
    if len(ordered) % 2:
        return ordered[mid]
    return (ordered[mid - 1] + ordered[mid]) // 2  # floor: the earlier step on a tie


def agreement(values: list[dict | None], tolerance_s: float, control_hz: int) -> tuple[dict, list[str]]:
    """Per-field agreement of K reviewers' resolved values -> (agreed values, disputed fields)."""
    if not values or any(v is None for v in values):
        return {}, list(FIELDS)
    agreed: dict = {}
    disputed: list[str] = []
    times = [v["fail_time_s"] for v in values]
    if max(times) - min(times) <= tolerance_s + 1e-9:
        step = agreed_step([snap_step(t, control_hz) for t in times])
        agreed["fail_time_s"], agreed["fail_step"] = grid_time(step, control_hz), step
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
