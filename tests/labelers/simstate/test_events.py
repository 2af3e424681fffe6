"""Each simstate rule on small synthetic evidence: what fires, what must not."""

from __future__ import annotations

from pipeline.labelers.simstate.events import (
    Thresholds,
    detect_events,
    goal_regression,
    grasp_lost_and_dropped,
    grasp_missed,
    robot_contacts,
    toppled,
)
from tests.stage2.evidence_factory import make_evidence

TH = Thresholds()


def test_a_close_near_an_object_that_grasps_nothing_is_a_missed_grasp():
    ev = make_evidence()
    ev.gripper_command[20:40] = 1.0
    ev.per_object["eef_distance"]["bowl_1"][:] = 0.05
    [e] = grasp_missed(ev, TH)
    assert (e.kind, e.step, e.object) == ("grasp_missed", 20, "bowl_1")


def test_a_one_step_gripper_flicker_is_not_a_grasp_attempt():
    ev = make_evidence()
    ev.gripper_command[20] = 1.0
    ev.per_object["eef_distance"]["bowl_1"][:] = 0.05
    assert grasp_missed(ev, TH) == []


def test_a_close_far_from_every_object_is_not_a_missed_grasp():
    ev = make_evidence()
    ev.gripper_command[20:40] = 1.0
    assert grasp_missed(ev, TH) == []


def test_a_grasp_that_slips_while_still_closed_is_grasp_lost():
    ev = make_evidence()
    ev.gripper_command[10:] = 1.0
    ev.grasped[12:30] = ["bowl_1"] * 18
    for t in range(30, 60):
        ev.contacts[t] = ["bowl_1|table"]
    [e] = grasp_lost_and_dropped(ev, TH)
    assert (e.kind, e.step) == ("grasp_lost", 30)


def test_an_unsupported_release_that_falls_is_a_drop_at_the_open_command():
    ev = make_evidence()
    ev.gripper_command[10:40] = 1.0
    ev.grasped[12:42] = ["bowl_1"] * 30
    ev.per_object["lift"]["bowl_1"][12:42] = 0.15
    [e] = grasp_lost_and_dropped(ev, TH)
    assert (e.kind, e.step, e.object) == ("object_dropped", 40, "bowl_1")


def test_a_release_while_resting_on_a_support_is_not_a_drop():
    ev = make_evidence()
    ev.gripper_command[10:40] = 1.0
    ev.grasped[12:42] = ["bowl_1"] * 30
    ev.per_object["lift"]["bowl_1"][12:42] = 0.05
    for t in range(38, 60):
        ev.contacts[t] = ["bowl_1|plate_1"]
    assert grasp_lost_and_dropped(ev, TH) == []


def test_a_topple_starts_where_the_tilt_began():
    ev = make_evidence()
    ev.per_object["tilt_deg"]["cup_1"][30:] = [5 * (t - 29) for t in range(30, 60)]
    [e] = toppled(ev, TH)
    assert (e.object, e.step) == ("cup_1", 32)  # tilt 5, 10 deg still calm; 15 deg starts it


def test_goal_progress_falling_for_five_steps_is_a_regression_and_a_blip_is_not():
    ev = make_evidence()
    ev.goal_progress[10:] = 1.0
    ev.goal_progress[20:22] = 0.0
    assert goal_regression(ev, TH) == []
    ev.goal_progress[40:] = 0.0
    [e] = goal_regression(ev, TH)
    assert e.step == 40


def test_robot_touching_an_object_the_goal_involves_is_not_a_non_target_contact():
    ev = make_evidence()
    for t in range(10, 20):
        ev.contacts[t] = ["bowl_1|robot", "plate_1|robot"]
    assert robot_contacts(ev, TH) == []
    for t in range(30, 40):
        ev.contacts[t] = ["cup_1|robot"]
    [e] = robot_contacts(ev, TH)
    assert (e.object, e.step) == ("cup_1", 30)


def test_events_come_back_sorted_by_step():
    ev = make_evidence()
    ev.gripper_command[40:50] = 1.0
    ev.per_object["eef_distance"]["bowl_1"][:] = 0.05
    for t in range(5, 12):
        ev.contacts[t] = ["cup_1|robot"]
    assert [e.step for e in detect_events(ev)] == [5, 40]
