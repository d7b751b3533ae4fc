"""Cartesian moves: speed limits, profiles, and the simulated clock."""

import math

import numpy as np
import pytest

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.motion import CartesianMove, MotionLimits, SimClock, trapezoid_progress, trapezoid_timing


def test_ten_centimetre_move_takes_distance_over_speed_plus_one_ramp():
    duration, ramp = trapezoid_timing(0.10, max_speed=0.06, max_accel=0.30)
    assert ramp == pytest.approx(0.2)
    assert duration == pytest.approx(0.10 / 0.06 + 0.2)


def test_short_move_is_triangular_and_never_reaches_top_speed():
    duration, ramp = trapezoid_timing(0.002, max_speed=0.06, max_accel=0.30)
    assert ramp == pytest.approx(duration / 2)
    assert duration == pytest.approx(2 * math.sqrt(0.002 / 0.30))


@pytest.mark.parametrize("distance", [0.0005, 0.01, 0.10])
def test_profile_respects_speed_limit_and_ends_at_one(distance):
    limits = MotionLimits()
    duration, ramp = trapezoid_timing(distance, limits.max_speed_m_s, limits.max_accel_m_s2)
    t = np.linspace(0, duration, 2001)
    s = np.array([trapezoid_progress(x, duration, ramp) for x in t])
    speed = np.diff(s * distance) / np.diff(t)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0)
    assert np.all(np.diff(s) >= -1e-15)
    assert speed.max() <= limits.max_speed_m_s * 1.001


def test_move_interpolates_straight_line_and_arrives_exactly():
    start = kin.pose_from_euler([0.02, 0.03, -0.15], 0.0, 0.1, -3.0)
    end = kin.pose_from_euler([0.06, 0.05, -0.16], 0.5, 0.1, -2.9)
    move = CartesianMove.plan(start, end, MotionLimits())
    np.testing.assert_allclose(move.pose_at(0.0), start, atol=1e-12)
    np.testing.assert_allclose(move.pose_at(move.duration_s), end, atol=1e-12)
    mid = move.pose_at(move.duration_s / 2)[:3, 3]
    np.testing.assert_allclose(mid, (start[:3, 3] + end[:3, 3]) / 2, atol=1e-12)
    assert len(move.waypoints(0.01)) == math.ceil(move.duration_s / 0.01)


def test_pure_rotation_takes_time_from_the_angular_limit():
    start = kin.pose_from_euler([0.04, 0.04, -0.16], -np.pi / 2, 0.0, -3.0)
    end = kin.pose_from_euler([0.04, 0.04, -0.16], np.pi / 2, 0.0, -3.0)
    limits = MotionLimits()
    move = CartesianMove.plan(start, end, limits)
    expected, _ = trapezoid_timing(np.pi, limits.max_angular_speed_rad_s, limits.max_angular_accel_rad_s2)
    assert move.duration_s == pytest.approx(expected)


def test_clock_counts_simulated_seconds_and_refuses_going_back():
    clock = SimClock()
    clock.advance(1.5)
    clock.advance(0.25)
    assert clock.time_s == pytest.approx(1.75)
    with pytest.raises(ValueError, match="forward"):
        clock.advance(-0.1)
    with pytest.raises(ValueError):
        clock.advance(float("nan"))
    clock.reset()
    assert clock.time_s == 0.0


def test_motion_limits_reject_non_positive_values():
    with pytest.raises(ValueError, match="max_speed_m_s"):
        MotionLimits(max_speed_m_s=0.0)
    with pytest.raises(ValueError, match="settle_time_s"):
        MotionLimits(settle_time_s=-1.0)
