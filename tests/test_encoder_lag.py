"""Tests for the reported-pose lag prototype: encoders that see part of the wrist's lag (sim.robot.cables, sim.world)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BIAS_PRESETS, BiasConfig
from dvrk_gym.sim.robot.cables import CableModel, hysteresis_output
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

_DEG = np.pi / 180.0
_START = np.array([10 * _DEG, -15 * _DEG, 0.15, -2.6, 5 * _DEG, -5 * _DEG])


def _config(kappa: float = 0.0, alpha: float = 0.0) -> BiasConfig:
    return dataclasses.replace(BIAS_PRESETS["paper"], encoder_backlash_fraction=kappa, wrist_settle_lag=alpha)


def test_fractions_outside_their_range_are_rejected() -> None:
    with pytest.raises(ValueError, match="encoder_backlash_fraction"):
        BiasConfig(encoder_backlash_fraction=1.5)
    with pytest.raises(ValueError, match="wrist_settle_lag"):
        BiasConfig(wrist_settle_lag=1.0)


def test_fractions_are_not_scaled_as_magnitudes() -> None:
    config = _config(kappa=0.6, alpha=0.3).scaled(2.0)
    assert config.encoder_backlash_fraction == 0.6 and config.wrist_settle_lag == 0.3


def test_by_default_the_encoders_report_the_command() -> None:
    model = CableModel(BIAS_PRESETS["paper"])
    model.reset(_START)
    q = _START + np.array([0, 0, 0, 0, 20 * _DEG, -20 * _DEG])
    model.true_joints(q)
    assert not model.reports_lag
    np.testing.assert_array_equal(model.measured_joints(q), q)


def test_full_kappa_reports_the_wrist_hysteresis_output() -> None:
    model = CableModel(_config(kappa=1.0))
    model.reset(_START)
    up = _START + np.array([0, 0, 0, 0, 20 * _DEG, 0])
    model.true_joints(up)
    measured = model.measured_joints(up)
    expected = hysteresis_output(model.get_state(), up)
    np.testing.assert_allclose(measured[3:], expected[3:])
    np.testing.assert_array_equal(measured[:3], up[:3])  # the outer joints and insertion: the command
    # After a 20-degree step up, wrist pitch reads short of the command by half the gap.
    assert measured[4] == pytest.approx(up[4] - _config().backlash_wrist_rad / 2)


def test_settle_lag_leaves_the_motors_a_fraction_of_the_wrist_step_short() -> None:
    alpha = 0.4
    model = CableModel(dataclasses.replace(BiasConfig(), wrist_settle_lag=alpha))
    model.reset(_START)
    step = np.array([0.01, 0.01, 0.001, 0.3, 20 * _DEG, -10 * _DEG])
    model.true_joints(_START + step)
    measured = model.measured_joints(_START + step)
    np.testing.assert_allclose(measured - _START, step * np.array([1, 1, 1, 1, 1 - alpha, 1 - alpha]))
    # No other error: the true joints are where the motors are; a second move to the same
    # command closes alpha of what is left (0.6 + 0.4 * 0.6 = 0.84 of the step).
    np.testing.assert_allclose(model.peek_true_joints(_START + step), _START + step * np.array([1, 1, 1, 1, 0.84, 0.84]))


def test_world_reports_the_measured_wrist_and_the_tip_moves_with_it() -> None:
    world = DvrkWorld(WorldConfig(bias=_config(alpha=0.5), camera_resolution=(320, 180)))
    try:
        world.reset_robot(_START)
        pose = kin.forward_kinematics(_START)
        turned = pose.copy()
        turned[:3, :3] = pose[:3, :3] @ np.array([[np.cos(0.3), 0, np.sin(0.3)], [0, 1, 0], [-np.sin(0.3), 0, np.cos(0.3)]])
        world.move_to(turned)
        reported = world.reported_pose()
        # A turn about the tool's y axis is a wrist-pitch step: the command kept the tool
        # frame where it was; the half-turned wrist (9.1 mm wrist offset) reports it elsewhere.
        assert np.linalg.norm(reported[:3, 3] - pose[:3, 3]) > 0.5e-3
        np.testing.assert_allclose(reported, kin.forward_kinematics(world.cable.measured_joints(world.q_cmd)))
    finally:
        world.close()
