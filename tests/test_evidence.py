"""Evidence recomputed from real logged LIBERO states (pipeline/evidence.py)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.evidence import read_evidence, write_evidence
from tests.stage2.conftest import episodes, evidences, spatial_env, stage1_run  # noqa: F401
from tests.stage2.evidence_factory import make_evidence
from tests.stage2.rollouts import OTHER_BOWL, TARGET, plan_step

@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_lifted_bowl_is_grasped_until_the_gripper_opens(evidences, stage1_run):
    ev = evidences["drop"]
    opened = plan_step(stage1_run, "drop", 6)
    lift = ev.col("lift", TARGET)
    assert lift[opened] > 0.1  # carried well above the table
    assert ev.grasped[opened - 1] == TARGET
    assert all(g == "" for g in ev.grasped[opened + 5 :])
    assert abs(lift[-1]) < 0.02  # back on the table


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_knocked_bowl_shows_displacement_and_robot_contact(evidences):
    ev = evidences["knock"]
    assert ev.col("displacement", OTHER_BOWL).max() > 0.1
    assert ev.col("displacement", TARGET).max() < 0.005
    assert any(f"{OTHER_BOWL}|robot" in c for c in ev.contacts)
    assert all(g == "" for g in ev.grasped)
    # the pair helpers read the same contacts: the rows the robot touches the knocked bowl
    hit = ev.pair_mask("robot", OTHER_BOWL)
    assert hit.any() and not ev.pair_mask("robot", TARGET).any()
    t = int(np.argmax(hit))
    assert "robot" in ev.touching_what(t, OTHER_BOWL) and ev.touching(t, OTHER_BOWL, "robot")


def test_touching_what_names_each_pair_partner_and_no_name_that_merely_contains_it():
    """Pairs are "a|b", sorted: a name that is another's prefix or suffix is not the same name."""
    ev = make_evidence(n=2, objects=("bowl_1", "black_bowl_1", "bowl_12"))
    ev.contacts[1] = ["black_bowl_1|table", "bowl_1|robot", "bowl_12|plate_1", "bowl_1|plate_1"]
    assert ev.touching_what(1, "bowl_1") == {"robot", "plate_1"}
    assert ev.touching_what(1, "black_bowl_1") == {"table"} and ev.touching_what(0, "bowl_1") == set()
    assert ev.pair_mask("plate_1", "bowl_1").tolist() == [False, True]


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_resting_objects_touch_the_named_table(evidences):
    assert "plate_1|table" in evidences["idle"].contacts[0]


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_goal_progress_reaches_one_only_in_the_successful_episode(evidences):
    assert evidences["success"].goal_progress[-1] == 1.0
    assert evidences["drop"].goal_progress.max() == 0.0


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_positions_match_the_free_joint_in_the_logged_states(evidences, spatial_env, stage1_run, episodes):
    states = np.load(stage1_run / "stage1" / episodes["drop"].path / "states.npy")
    adr = spatial_env.free_joints()[TARGET]
    logged = states[:, 1 + adr : 1 + adr + 3]  # flattened state = (time, qpos, qvel)
    np.testing.assert_allclose(evidences["drop"].col("position", TARGET), logged, atol=1e-5)


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_evidence_file_round_trips_every_column(evidences, tmp_path):
    ev = evidences["knock"]
    write_evidence(tmp_path / "e.parquet", ev)
    back = read_evidence(tmp_path / "e.parquet")
    assert back.grasped == ev.grasped and back.contacts == ev.contacts and back.goal == ev.goal
    np.testing.assert_array_equal(back.gripper_command, ev.gripper_command)
    for col, per in ev.per_object.items():
        for obj, values in per.items():
            np.testing.assert_array_equal(back.col(col, obj), values, err_msg=f"{col}/{obj}")


def test_read_evidence_rejects_a_parquet_that_is_not_evidence(tmp_path):
    path = tmp_path / "other.parquet"
    pq.write_table(pa.table({"step": [0, 1]}), path)
    with pytest.raises(ValueError, match="other.parquet"):
        read_evidence(path)
