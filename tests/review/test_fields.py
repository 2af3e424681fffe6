from __future__ import annotations

import pytest

from pipeline.review.fields import FieldError, agreement, resolve, validate_field

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
    out = resolve(PROPOSAL, {"fail_time_s": 2.26}, duration_s=10.0, control_hz=20)
    assert out["fail_time_s"] == 2.26 and out["fail_step"] == 45 and out["recovery_level"] == "L2"


def test_resolve_rejects_unknown_fields():
    with pytest.raises(FieldError) as e:
        resolve(PROPOSAL, {"recovery_lvl": "L1"}, 10.0, 20)
    assert e.value.field == "recovery_lvl"


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
