"""Motion primitives and noise of the scripted expert (pure, no simulator)."""

from __future__ import annotations

import numpy as np

from pipeline.config import ScriptedNoise
from pipeline.policies.scripted.noise import Noise, episode_rng
from pipeline.policies.scripted.primitives import (
    TOP_DOWN,
    Grip,
    Move,
    emit,
    hand_orientation,
    rotation_error,
    yaw_matrix,
)


def test_move_emits_saturated_actions_towards_the_target():
    move = Move(target=np.array([0.3, 0.0, 1.0]), speed=0.8)
    chunk = emit(move, np.array([0.0, 0.0, 1.0]), TOP_DOWN, 8, 0.0)
    assert chunk.shape == (8, 7)
    assert np.all(chunk[:, 0] > 0) and np.all(np.abs(chunk[:, :3]) <= 0.8 + 1e-12)
    assert np.all(chunk[:, 6] == -1.0)


def test_move_chunk_ends_early_once_arrival_is_predicted():
    move = Move(target=np.array([0.0, 0.0, 1.004]), tol=0.01)
    chunk = emit(move, np.array([0.0, 0.0, 1.0]), TOP_DOWN, 8, 0.0)
    assert 1 <= len(chunk) < 8


def test_grip_emits_only_its_remaining_steps():
    grip = Grip(1.0, n=5)
    grip.steps = 2
    chunk = emit(grip, np.zeros(3), TOP_DOWN, 8, 0.0)
    assert chunk.shape == (3, 7) and np.all(chunk[:, 6] == 1.0) and np.allclose(chunk[:, :3], 0)


def test_rotation_error_recovers_a_yaw_turn():
    err = rotation_error(yaw_matrix(0.4) @ TOP_DOWN, TOP_DOWN)
    assert np.allclose(err, [0, 0, 0.4], atol=1e-9)
    assert np.allclose(rotation_error(TOP_DOWN, TOP_DOWN), 0)


def test_tilted_hand_points_along_the_approach_with_vertical_fingers():
    r = hand_orientation(0.0, np.array([0.0, -1.0, 0.0]))
    assert np.allclose(r[:, 2], [0, -1, 0], atol=1e-9)  # gripper axis
    assert np.allclose(np.abs(r[:, 0]), [0, 0, 1], atol=1e-9)  # fingers close vertically


def test_an_approach_pointing_partly_down_pitches_the_hand_by_its_angle():
    a = np.array([0.0, np.sin(0.9), -np.cos(0.9)])
    r = hand_orientation(np.pi / 2, a)
    assert np.allclose(r[:, 2], a, atol=1e-9)  # the gripper axis points along the approach
    assert np.allclose(hand_orientation(0.3, np.array([0.0, 0.0, -1.0])), hand_orientation(0.3))


def test_same_seed_and_task_draw_the_same_noise_and_other_seeds_do_not():
    levels = ScriptedNoise(grasp_offset_m=0.01, action_noise=0.1, speed_scale=0.3, gripper_timing_steps=3)
    a = Noise(levels, episode_rng(7, "libero_spatial/x"))
    b = Noise(levels, episode_rng(7, "libero_spatial/x"))
    c = Noise(levels, episode_rng(8, "libero_spatial/x"))
    assert a.speed == b.speed and np.array_equal(a.grasp_offset(), b.grasp_offset())
    assert not np.array_equal(a.grasp_offset(), c.grasp_offset())
    assert all(-3 <= a.timing() <= 3 for _ in range(50))


def test_zero_noise_changes_nothing():
    n = Noise(ScriptedNoise(), episode_rng(0, "t"))
    chunk = np.full((4, 7), 0.5)
    assert n.speed == 1.0 and np.array_equal(n.actions(chunk), chunk)
    assert np.array_equal(n.grasp_offset(), np.zeros(3)) and n.timing() == 0
