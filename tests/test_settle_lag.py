"""The wrist that settles short of its command (BiasConfig.wrist_settle_lag): the motors, the
cables behind them and the encoders that report them (sim.robot.cables, sim.world)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dvrk_gym.sim import identified
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BIAS_PRESETS, BiasConfig
from dvrk_gym.sim.robot.cables import CableModel
from dvrk_gym.sim.table.table import DebridementTable
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

_DEG = np.pi / 180.0
_START = np.array([10 * _DEG, -15 * _DEG, 0.15, -2.6, 5 * _DEG, -5 * _DEG])


_NO_BIAS = BiasConfig()


def _lagging(alpha: float, base: BiasConfig = _NO_BIAS) -> BiasConfig:
    return dataclasses.replace(base, wrist_settle_lag=alpha)


def test_a_lag_outside_zero_to_one_is_rejected_and_not_scaled() -> None:
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match="wrist_settle_lag"):
            BiasConfig(wrist_settle_lag=bad)
    assert _lagging(0.3).scaled(2.0).wrist_settle_lag == 0.3  # a fraction, not a magnitude


def test_the_paper_preset_carries_the_identified_lag_and_severe_keeps_it() -> None:
    assert BIAS_PRESETS["paper"].wrist_settle_lag == identified.WRIST_SETTLE_LAG > 0.0
    assert BIAS_PRESETS["severe"].wrist_settle_lag == identified.WRIST_SETTLE_LAG
    assert BIAS_PRESETS["none"].wrist_settle_lag == 0.0


def test_without_a_lag_the_encoders_report_the_command() -> None:
    model = CableModel(_lagging(0.0, BIAS_PRESETS["paper"]))
    model.reset(_START)
    q = _START + np.array([0, 0, 0, 0, 20 * _DEG, -20 * _DEG])
    model.true_joints(q)
    np.testing.assert_array_equal(model.measured_joints(q), q)


def test_the_motors_stop_a_fraction_of_the_wrist_step_short() -> None:
    alpha = 0.4
    model = CableModel(_lagging(alpha))
    model.reset(_START)
    step = np.array([0.01, 0.01, 0.001, 0.3, 20 * _DEG, -10 * _DEG])
    model.true_joints(_START + step)
    measured = model.measured_joints(_START + step)
    # Only wrist pitch and wrist yaw lag; with no other error the true joints are the motors'.
    np.testing.assert_allclose(measured - _START, step * np.array([1, 1, 1, 1, 1 - alpha, 1 - alpha]))
    # A second move to the same command closes alpha of what is left: 0.6 + 0.4 * 0.6 = 0.84.
    np.testing.assert_allclose(model.peek_true_joints(_START + step), _START + step * np.array([1, 1, 1, 1, 0.84, 0.84]))


def test_the_state_carries_the_motors_so_a_restored_move_repeats_bit_for_bit() -> None:
    model = CableModel(_lagging(0.3, BIAS_PRESETS["paper"]))
    model.reset(_START)
    rng = np.random.default_rng(4)
    for _ in range(5):
        model.true_joints(_START + rng.normal(scale=0.1, size=6) * [1, 1, 0.01, 1, 1, 1])
    saved = model.get_state()
    target = _START + np.array([0, 0, 0, 0.2, -15 * _DEG, 10 * _DEG])
    expected, expected_measured = model.true_joints(target), model.measured_joints(target)
    model.true_joints(_START)  # wander off: plays and motors move
    model.set_state(saved)
    np.testing.assert_array_equal(model.true_joints(target), expected)
    np.testing.assert_array_equal(model.measured_joints(target), expected_measured)
    with pytest.raises(ValueError, match="shape"):
        model.set_state(saved[:-1])  # the plays alone


def test_the_world_reports_the_lagging_wrist_and_the_tip_with_it() -> None:
    world = DvrkWorld(WorldConfig(bias=_lagging(0.5, BIAS_PRESETS["paper"]), camera_resolution=(320, 180)))
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


def test_a_point_of_a_move_settles_from_where_the_move_began_and_resting_joints_do_not_move() -> None:
    model = CableModel(_lagging(0.4, BIAS_PRESETS["paper"]))
    model.reset(_START)
    target = _START + np.array([0.02, -0.01, 0.002, 0.2, 15 * _DEG, -10 * _DEG])
    expected = model.true_joints(target)
    start = model.get_state()[-1]
    # The noiseless joints where that move left the arm, read without moving anything;
    # peek_true_joints would settle the wrist once more (0.4 of what is left).
    np.testing.assert_array_equal(model.resting_true_joints(target), expected)
    np.testing.assert_array_equal(model.get_state()[-1], start)
    assert np.abs(model.peek_true_joints(target) - expected)[4:].min() > 1e-3
    # Points along the next move settle from where it began, however many are sampled.
    end = target + np.array([0, 0, 0, 0, -25 * _DEG, 20 * _DEG])
    one_call = CableModel(_lagging(0.4, BIAS_PRESETS["paper"]))
    one_call.set_state(model.get_state())
    for fraction in np.linspace(0.0, 1.0, 30)[1:]:
        model.true_joints(target + fraction * (end - target), settle_from=start)
    one_call.true_joints(end)
    np.testing.assert_allclose(model.measured_joints(end), one_call.measured_joints(end), rtol=0, atol=1e-12)
    assert np.abs(model.measured_joints(end) - end)[4:].min() > 1e-2  # still short, by 0.4 of the step
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    drawn = model.repeatability_draw(rng_a)
    np.testing.assert_allclose(model.true_joints(end, rng_b) - model.resting_true_joints(end), drawn, rtol=0, atol=1e-15)


def test_a_stepped_move_leaves_the_wrist_as_short_of_its_command_as_move_to_does() -> None:
    """The stepped moves of the picks and move_to settle the wrist once a move (before, a
    stepped move settled it at every physics step: after a turn of the wrist its encoders
    lagged by under 0.001 degrees, against 3 to 5 through move_to)."""
    ends = []
    for stepped in (False, True):
        world = DvrkWorld(WorldConfig(bias="paper", camera_resolution=(320, 180)))
        try:
            table = DebridementTable(world)
            table.add_fragments("raisin", np.random.default_rng(0), n=1)
            world.reset_robot(_START)
            world.move_to(kin.forward_kinematics(_START + np.array([0, 0, 0, 0, -15 * _DEG, 10 * _DEG])))
            before = world.reported_pose()
            if stepped:
                start = world.q_true.copy()
                table.move_stepped(before, duration_s=0.05)  # a move that stays where it is
                # The start of the move is where the last one left the arm: no jump.
                np.testing.assert_allclose(world.reported_pose(), before, rtol=0, atol=1e-9)
                assert np.linalg.norm(world.q_true - start) < 1e-9  # the old code moved it 2.4 degrees
            pose = kin.forward_kinematics(_START + np.array([0.01, 0, 0, 0.1, 20 * _DEG, -20 * _DEG]))
            (table.move_stepped(pose) if stepped else world.move_to(pose))
            ends.append(world.cable.measured_joints(world.q_cmd) - world.q_cmd)
        finally:
            world.close()
    assert np.abs(ends[0][4:]).min() > 1.0 * _DEG
    np.testing.assert_allclose(ends[1], ends[0], rtol=0, atol=0.05 * _DEG)
