"""Pre / during / post phases and the seconds <-> steps mapping."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from pipeline.records import FRAME_SCHEMA
from pipeline.stage2.phases import split_phases, step_for_time
from tests.stage2.evidence_factory import make_evidence
from tests.stage2.rollouts import TARGET


def test_during_ends_once_objects_have_been_still_for_the_settle_window():
    ev = make_evidence(n=80)
    ev.per_object["speed"]["cup_1"][20:35] = 0.5
    p = split_phases(ev, onset=20, settle_speed_mps=0.01, settle_steps=10)
    assert (p.pre, p.during, p.post) == ((0, 20), (20, 45), (45, 80))


def test_during_ends_early_when_the_robot_abandons_the_attempt():
    ev = make_evidence(n=80)
    ev.per_object["speed"]["cup_1"][20:70] = 0.5
    ev.gripper_command[20:30] = 1.0  # closed at the onset, opened again at 30
    p = split_phases(ev, onset=20, settle_speed_mps=0.01, settle_steps=10)
    assert p.during == (20, 30)


def test_a_scene_never_settling_runs_during_to_the_last_state():
    ev = make_evidence(n=50)
    ev.per_object["speed"]["cup_1"][:] = 0.5
    ev.gripper_command[:] = 1.0
    p = split_phases(ev, onset=10, settle_speed_mps=0.01, settle_steps=10)
    assert p.during == (10, 50) and p.post == (50, 50)


def test_an_onset_outside_the_episode_is_refused():
    with pytest.raises(ValueError, match="onset step 60"):
        split_phases(make_evidence(n=60), onset=60, settle_speed_mps=0.01, settle_steps=10)


def test_seconds_map_to_steps_through_the_frame_table():
    frames = pa.Table.from_pylist([{"frame": i, "step": 2 * i, "time_s": i / 10} for i in range(30)], FRAME_SCHEMA)
    assert step_for_time(2.35, frames, steps=58) == 47  # between frames 23 and 24
    assert step_for_time(2.9, frames, steps=58) == 58
    assert step_for_time(99.0, frames, steps=58) == 58  # clamped to the episode
    assert step_for_time(1.26, None, steps=58) == 25


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_the_drop_phase_lasts_until_the_fallen_bowl_is_at_rest(evidences):
    from pipeline.labelers.simstate.localizer import localize

    ev = evidences["drop"]
    onset = localize(ev).onset_step
    p = split_phases(ev, onset, settle_speed_mps=0.01, settle_steps=10)
    lift = ev.col("lift", TARGET)
    end = p.during[1]
    assert lift[end - 1] < 0.02 < lift[onset]  # the fall is inside the during phase
    assert ev.col("speed", TARGET)[end - 10 : end].max() < 0.01
    assert p.post == (end, len(ev))


def test_a_scene_is_not_settled_while_the_gripper_fingers_still_open():
    """Objects at rest but the fingers opening: a restore would close them (the state has no
    gripper command) and knock what stands beside them, so the scene waits for the fingers."""
    from pipeline.stage2.phases import settled_step

    ev = make_evidence(n=80)
    ev.per_object["speed"]["cup_1"][20:25] = 0.5
    ev.gripper_opening[:] = 0.0
    ev.gripper_opening[30:40] = np.linspace(0.0, 0.08, 10)  # opening at 16 cm/s (0.8 cm a step)
    ev.gripper_opening[40:] = 0.08
    assert settled_step(ev, onset=20, speed_mps=0.01, settle_steps=10) == 40
    ev.gripper_opening[30:] = 0.0  # fingers still: the objects alone decide
    assert settled_step(ev, onset=20, speed_mps=0.01, settle_steps=10) == 25
    ev.gripper_opening[:30] = 0.08
    ev.gripper_opening[30:40] = np.linspace(0.08, 0.0, 10)  # closing: a restore closes them too
    assert settled_step(ev, onset=20, speed_mps=0.01, settle_steps=10) == 25
