"""The cable model's signs, units and magnitudes, one error term at a time.

The statistics tests (test_bias.py) check what the terms do together; a term with the
wrong sign can hide among them (the gravity sag once lifted the shaft instead of lowering
it, about 0.3 mm at the tip, and every test passed). Here each term acts alone on a
model whose other magnitudes are zero, and its direction and size are pinned in the
units its BiasConfig field names.
"""

import math

import numpy as np
import pytest

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig
from dvrk_gym.sim.robot.cables import INSERTION_MAX_M, OUTER_STRETCH_SCALE_RAD, OUTER_UNLOADED_RAD, CableModel

DEG = math.pi / 180.0
TILTED = np.array([0.0, -40 * DEG, 0.20, 0.0, 0.0, 0.0])
"""A shaft pitched 40 degrees from the vertical, 20 cm in."""


def _error(config: BiasConfig, q: np.ndarray, seed: int = 0) -> np.ndarray:
    model = CableModel(config, bias_seed=seed)
    model.reset(q)
    return model.true_joints(q) - q


def _tip(q: np.ndarray) -> np.ndarray:
    return kin.forward_kinematics(q)[:3, 3]


@pytest.mark.parametrize("pitch_deg", [-40.0, -20.0, 20.0, 40.0])
@pytest.mark.parametrize("yaw_deg", [-30.0, 0.0, 30.0])
def test_gravity_sag_lowers_the_tip(pitch_deg, yaw_deg):
    q = np.array([yaw_deg * DEG, pitch_deg * DEG, 0.20, 0.0, 0.0, 0.0])
    sagged = q + _error(BiasConfig(sag_m=1e-3), q)
    drop = _tip(q)[2] - _tip(sagged)[2]
    assert drop > 0.0  # down, never up
    shaft = _tip(q) / np.linalg.norm(_tip(q))
    tilt = math.acos(-shaft[2])
    # a cantilever turned toward the vertical by sag / L_max * (d / L_max)^2 * sin(tilt): the tip drops by d * angle * sin(tilt)
    expected = 0.20 * (1e-3 / INSERTION_MAX_M) * (0.20 / INSERTION_MAX_M) ** 2 * math.sin(tilt) ** 2
    assert drop == pytest.approx(expected, rel=0.05)


def test_gravity_sag_is_in_metres_and_grows_with_insertion():
    half, full = TILTED.copy(), TILTED.copy()
    half[2], full[2] = 0.10, INSERTION_MAX_M
    drops = []
    for q in (half, full):
        drops.append(_tip(q)[2] - _tip(q + _error(BiasConfig(sag_m=1e-3), q))[2])
    assert drops[1] == pytest.approx(1e-3 * math.sin(40 * DEG) ** 2, rel=0.05)  # 1 mm for a horizontal shaft at full insertion
    assert drops[0] == pytest.approx(drops[1] * (0.10 / INSERTION_MAX_M) ** 3, rel=0.05)
    vertical = np.array([0.0, 0.0, 0.20, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(_error(BiasConfig(sag_m=1e-3), vertical), 0.0, atol=1e-15)  # hanging straight: no sag


def test_outer_stretch_follows_the_deflection_from_the_unloaded_pose():
    config = BiasConfig(outer_stretch_rad=2.6 * DEG)
    for sign in (1.0, -1.0):
        q = np.array([*(OUTER_UNLOADED_RAD + sign * 4 * DEG), 0.18, 0.0, 0.0, 0.0])
        errors = np.array([_error(config, q, seed)[:2] for seed in range(20)])
        assert np.all(np.sign(errors) == sign)  # more load, more stretch, in the same direction
        expected = 2.6 * DEG * math.tanh(4 * DEG / OUTER_STRETCH_SCALE_RAD)
        assert np.mean(np.abs(errors)) == pytest.approx(expected, rel=0.1)  # radians, gains near 1
    q = np.array([*OUTER_UNLOADED_RAD, 0.18, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(_error(config, q)[:2], 0.0, atol=1e-15)
    far = np.array([*(OUTER_UNLOADED_RAD + 80 * DEG), 0.18, 0.0, 0.0, 0.0])
    assert np.all(np.abs(_error(config, far)[:2]) < 1.5 * 2.6 * DEG)  # saturates near the magnitude


def test_wrist_stretch_follows_the_wrist_deflection():
    config = BiasConfig(wrist_stretch=0.07)
    for sign in (1.0, -1.0):
        q = np.array([0.0, -20 * DEG, 0.18, 0.0, sign * 20 * DEG, 0.0])
        error = _error(config, q)
        assert np.sign(error[4]) == sign  # wrist pitch error along its deflection
        assert abs(error[4]) == pytest.approx(0.07 * 30 * DEG * math.tanh(20 / 30), rel=0.35)  # rad per rad, about 1 deg
        assert np.all(error[:3] == 0.0)
    np.testing.assert_allclose(_error(config, np.array([0.0, 0.0, 0.18, 1.0, 0.0, 0.0])), 0.0, atol=1e-15)


@pytest.mark.parametrize(("field", "joints"), [("homing_offset_rad", [0, 1, 3, 4, 5]), ("homing_offset_m", [2])])
def test_homing_offsets_have_the_configured_spread_in_their_unit(field, joints):
    config = BiasConfig(**{field: 0.01})
    errors = np.array([_error(config, TILTED, seed) for seed in range(300)])
    spread = errors[:, joints].std()
    assert spread == pytest.approx(0.01, rel=0.15)
    others = [j for j in range(6) if j not in joints]
    assert np.all(errors[:, others] == 0.0)


def test_backlash_gap_and_the_side_each_approach_lands_on():
    gap = 0.4 * DEG
    model = CableModel(BiasConfig(backlash_outer_rad=gap))
    target = TILTED.copy()
    model.reset(target - [2 * DEG, 0, 0, 0, 0, 0])
    from_below = model.true_joints(target)[0]
    model.reset(target + [2 * DEG, 0, 0, 0, 0, 0])
    from_above = model.true_joints(target)[0]
    assert from_below < target[0] < from_above  # the cables lag behind the command
    assert from_above - from_below == pytest.approx(gap, rel=1e-9)  # the configured gap, radians


def test_repeatability_scatters_the_tip_by_the_configured_rms_in_metres():
    model = CableModel(BiasConfig(repeatability_m=1e-4))
    rng = np.random.default_rng(0)
    nominal = kin.touch_point(TILTED)
    tips = np.array([kin.touch_point(model.true_joints(TILTED, rng)) for _ in range(2000)])
    rms = float(np.sqrt(np.mean(np.sum((tips - nominal) ** 2, axis=1))))
    assert rms == pytest.approx(1e-4, rel=0.35)


def test_tool_length_error_is_in_metres():
    model = CableModel(BiasConfig(tool_length_m=1e-3), bias_seed=3)
    shaft = model.true_dh[3].d_offset_m - kin.PSM_DH[3].d_offset_m
    wrist = model.true_dh[5].a_m - kin.PSM_DH[5].a_m
    lengths = []
    for seed in range(200):
        dh = CableModel(BiasConfig(tool_length_m=1e-3), bias_seed=seed).true_dh
        lengths += [dh[3].d_offset_m - kin.PSM_DH[3].d_offset_m, dh[5].a_m - kin.PSM_DH[5].a_m]
    assert np.std(lengths) == pytest.approx(1e-3, rel=0.15)
    assert abs(shaft) < 5e-3 and abs(wrist) < 5e-3
