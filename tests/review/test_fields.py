from __future__ import annotations

import pytest

from pipeline.review.fields import FieldError, agreement, edited_fields, resolve, validate_field

PROPOSAL = {"fail_time_s": 2.0, "recovery_level": "L2", "failure_category": "grasp_failure",
            "recovery_action": "Grasp the bowl again"}


def vals(**kw):
    return {**PROPOSAL, "fail_step": 40, **kw}


def test_validate_field_names_the_field_and_the_allowed_values():
    with pytest.raises(FieldError) as e:
        validate_field("failure_category", "gripper_slip", 10.0)
    assert e.value.field == "failure_category" and "grasp_failure" in str(e.value)


@pytest.mark.parametrize("bad", [-0.1, 10.5, float("nan"), "2.0", True])
def test_failure_time_must_be_a_number_inside_the_episode(bad):
    with pytest.raises(FieldError, match="fail_time_s"):
        validate_field("fail_time_s", bad, 10.0)


def test_resolve_overlays_edits_and_derives_the_step():
    out = resolve(PROPOSAL, {"fail_time_s": 2.3}, duration_s=10.0, control_hz=20)
    assert out["fail_time_s"] == 2.3 and out["fail_step"] == 46 and out["recovery_level"] == "L2"


@pytest.mark.parametrize("given, stored, step", [(2.26, 2.25, 45), (2.275, 2.3, 46), (2.9500000000000002, 2.95, 59),
                                                 (3.0749, 3.05, 61), (0.0, 0.0, 0), (9.98, 9.95, 199)])
def test_failure_times_are_snapped_to_the_control_grid(given, stored, step):
    # 9.98 s would snap past the end of a 9.98 s episode: the last step inside it
    out = resolve(PROPOSAL, {"fail_time_s": given}, duration_s=9.98, control_hz=20)
    assert (out["fail_time_s"], out["fail_step"]) == (stored, step)


def test_setting_the_models_own_time_or_action_is_not_an_edit():
    model = {**PROPOSAL, "fail_time_s": 2.95}
    values = resolve(model, {"fail_time_s": 2.95000001, "recovery_action": "grasp the bowl  again."}, 10.0, 20)
    assert edited_fields(model, values, 20) == []
    values = resolve(model, {"fail_time_s": 3.0}, 10.0, 20)
    assert edited_fields(model, values, 20) == ["fail_time_s"]


def test_resolve_rejects_unknown_fields():
    with pytest.raises(FieldError) as e:
        resolve(PROPOSAL, {"recovery_lvl": "L1"}, 10.0, 20)
    assert e.value.field == "recovery_lvl"


@pytest.mark.parametrize("times, agreed", [([2.95, 3.2], 3.05), ([2.95, 3.0], 2.95), ([2.95, 3.05], 3.0),
                                           ([2.0, 2.1, 2.45], 2.1), ([2.0, 2.05, 2.3, 2.4], 2.15)])
def test_the_agreed_time_is_the_median_step_with_ties_to_the_earlier_step(times, agreed):
    out, disputed = agreement([vals(fail_time_s=t) for t in times], 0.5, 20)
    assert disputed == [] and out["fail_time_s"] == agreed and out["fail_step"] == round(agreed * 20)


def test_times_within_tolerance_agree_and_beyond_it_do_not():
    agreed, disputed = agreement([vals(fail_time_s=2.0), vals(fail_time_s=2.5)], 0.5, 20)
    assert disputed == [] and agreed["fail_time_s"] == 2.25 and agreed["fail_step"] == 45
    _, disputed = agreement([vals(fail_time_s=2.0), vals(fail_time_s=2.51)], 0.5, 20)
    assert disputed == ["fail_time_s"]


def test_actions_agree_when_the_text_is_the_same_up_to_case_spaces_and_full_stop():
    _, disputed = agreement([vals(recovery_action="Grasp the bowl again."), vals(recovery_action=" grasp the  bowl again")],
                            0.5, 20)
    assert disputed == []
    _, disputed = agreement([vals(), vals(recovery_action="Regrasp the bowl")], 0.5, 20)
    assert disputed == ["recovery_action"]


def test_three_reviewers_must_all_agree_on_a_field():
    _, disputed = agreement([vals(), vals(), vals(recovery_level="L3")], 0.5, 20)
    assert disputed == ["recovery_level"]


def test_a_flag_disputes_every_field():
    agreed, disputed = agreement([vals(), None], 0.5, 20)
    assert agreed == {} and set(disputed) == {"fail_time_s", "recovery_level", "failure_category", "recovery_action"}
