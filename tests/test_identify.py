"""Identification of the instrument from the real rows (dvrk_gym.fidelity.instrument_model, .identify, .detector_noise)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity import detector_noise
from dvrk_gym.fidelity.identify import (
    CAMERA_AND_TAPE,
    HUBER_SCALE,
    InstrumentFit,
    fit_parameters,
    huber_residuals,
    prior_residuals,
    refit,
    repeatability_from_jitter,
    residual_rms,
    split,
    start_camera_pose,
    start_values,
    theta_of,
)
from dvrk_gym.fidelity.instrument_model import (
    PARAMETER_NAMES,
    PARAMETERS,
    _wrist_yaw_frames,
    cable_model,
    initial_vector,
    predict_camera_points,
    predict_pixels,
    real_commands,
    real_pixels,
)
from dvrk_gym.fidelity.settle_lag import first_crossing, match_settle_lag
from dvrk_gym.sim import identified
from dvrk_gym.sim.endoscope.noise import IDENTIFIED_MARKER_NOISE, DetectionNoise
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.sim.world import DvrkWorld
from dvrk_gym.sim.world_config import WorldConfig


@pytest.fixture(scope="module")
def rows():
    X, y = load_paper_phase1()
    return X, y, real_commands(X, y)


def _identified_vector() -> np.ndarray:
    """The parameter vector of the identified instrument (sim.identified)."""
    theta = initial_vector(np.eye(4))
    values = {
        "log_depth_scale": np.log(identified.CAMERA.depth_scale),
        "homing_insertion": identified.INSTRUMENT.homing_offsets[2],
        "homing_roll": identified.INSTRUMENT.homing_offsets[3],
        "homing_wrist_pitch": identified.INSTRUMENT.homing_offsets[4],
        "outer_stretch_yaw": identified.INSTRUMENT.outer_stretch_rad[0],
        "outer_stretch_pitch": identified.INSTRUMENT.outer_stretch_rad[1],
        "wrist_stretch": identified.INSTRUMENT.wrist_stretch,
        "backlash_outer": identified.INSTRUMENT.backlash_outer_rad,
        "backlash_wrist": identified.INSTRUMENT.backlash_wrist_rad,
    }
    for name, value in values.items():
        theta[PARAMETER_NAMES.index(name)] = value
    theta[0:3] = identified.CAMERA.rotation_vector
    theta[3:6] = identified.CAMERA.position_base_m
    theta[7:10] = identified.MARKER_OFFSET_M
    return theta


def test_the_rows_are_whole_pixels_of_the_authors_cameras():
    X, _ = load_paper_phase1()
    pixels = real_pixels(X)
    np.testing.assert_allclose(pixels[:, :2], np.round(pixels[:, :2]), atol=1e-6)


def test_row_differences_give_back_the_authors_disparities_and_23_percent_over_2_px():
    X, _ = load_paper_phase1()
    differences = detector_noise.row_differences(X)
    disparity = paper.ENDOSCOPE_FOCAL_PX * paper.ENDOSCOPE_BASELINE_M / X[:, 2]
    horizontal = np.sqrt(disparity**2 - differences**2)
    np.testing.assert_allclose(horizontal, np.round(horizontal), atol=1e-6)
    assert detector_noise.histogram(differences)[:5].tolist() == [455, 677, 356, 186, 105]
    assert np.mean(differences > 2) == pytest.approx(0.233, abs=0.001)


def test_row_differences_refuse_rows_from_another_triangulation():
    X, _ = load_paper_phase1()
    shifted = X[:5].copy()
    shifted[:, 2] *= 1.001
    with pytest.raises(ValueError, match="no length of whole pixels"):
        detector_noise.row_differences(shifted)
    near = X[:3].copy()  # disparities under the 40 rows searched: a row difference above one is no answer
    near[:, 2] = paper.ENDOSCOPE_FOCAL_PX * paper.ENDOSCOPE_BASELINE_M / np.array([30.3, 12.7, 5.5])
    with pytest.raises(ValueError, match="rows \\[0, 1, 2\\] have a disparity"):
        detector_noise.row_differences(near)


def test_detector_noise_fit_recovers_the_noise_that_made_a_histogram():
    truth = DetectionNoise(0.9, 3.0, 0.25)
    counts = np.round(detector_noise.row_difference_probabilities(truth) * 1e6)
    fitted = detector_noise.fit_detector_noise(counts)
    assert fitted.core_px == pytest.approx(0.9, abs=0.05)
    assert fitted.outlier_px == pytest.approx(3.0, abs=0.15)
    assert fitted.outlier_probability == pytest.approx(0.25, abs=0.03)
    assert detector_noise.held_out_pvalue(fitted, counts / 1e4) > 0.5


def test_batched_frames_are_the_kinematics_frames(rows):
    _, _, commands = rows
    np.testing.assert_allclose(_wrist_yaw_frames(commands[:20]), [kin.link_frames(q)[5] for q in commands[:20]], atol=1e-12)


def test_the_cable_model_of_a_vector_is_the_simulators_identified_one(rows):
    _, _, commands = rows
    model = cable_model(_identified_vector())
    np.testing.assert_allclose(model.instrument.homing_offsets, identified.INSTRUMENT.homing_offsets)
    # and it moves as the simulator's paper instrument does: the same true joints along the
    # same commands (stretch, coupling and backlash with their history), noise and the wrist's
    # settle lag aside (matched afterwards, to the rows' sequence: identified.WRIST_SETTLE_LAG)
    settled = dataclasses.replace(BIAS_PRESETS["paper"], wrist_settle_lag=0.0)
    simulator = DvrkWorld(WorldConfig(bias=settled)).cable
    for cables in (model, simulator):
        cables.reset(commands[0])
    for q in commands[1:200]:
        np.testing.assert_allclose(model.true_joints(q), simulator.true_joints(q), rtol=0, atol=1e-12)


def test_the_identified_instrument_predicts_the_held_out_rows_as_stated(rows):
    X, _, commands = rows
    _, held_out = split(len(X))
    rms = residual_rms(_identified_vector(), commands[held_out], real_pixels(X)[held_out])
    np.testing.assert_allclose(rms, identified.FIT_RESIDUALS["full, held out"], atol=0.02)
    camera_error = predict_camera_points(_identified_vector(), commands[held_out]) - X[held_out, :3]
    assert np.sqrt(np.mean(camera_error[:, :2] ** 2)) < 1.2e-3  # image plane: about 1 mm


@pytest.mark.slow
def test_a_camera_and_tape_fit_from_the_start_finds_the_paper_camera(rows):
    X, _, commands = rows
    train, _ = split(len(X), 0.3)
    fit = fit_parameters(commands[train], real_pixels(X)[train], free=CAMERA_AND_TAPE)
    # From 0.19 m above the workspace centre to near the identified camera (the cable terms
    # of the full fit move it by about 8 mm), leaving about 8 px in u and v (measured on the
    # first 70%: 8.2 px; the full model: 6.4 px) and the detector's 2.7 px in disparity.
    assert np.linalg.norm(start_camera_pose()[:3, 3] - identified.CAMERA.position_base_m) > 0.05
    assert np.linalg.norm(fit.theta[3:6] - identified.CAMERA.position_base_m) < 0.015
    rms = residual_rms(fit.theta, commands[train], real_pixels(X)[train])
    assert np.all(rms[:2] < 10.0) and rms[2] < 3.0


@pytest.mark.slow
def test_a_camera_and_tape_fit_finds_one_camera_from_starts_tilted_other_ways(rows):
    # Fitted in the absolute rotation vector of a camera looking down (near a half turn), a
    # start differing in its last bit (6e-17) ended about 90 mm away; as a turn of the start, not.
    from scipy.spatial.transform import Rotation

    X, _, commands = rows
    train, _ = split(len(X), 0.3)
    pixels = real_pixels(X)[train]
    positions = []
    for azimuth in (-np.pi / 2, np.pi / 2):  # -pi/2: start_camera_pose's tilt
        start = start_camera_pose()
        tilt = Rotation.from_rotvec(np.array([np.cos(azimuth), np.sin(azimuth), 0.0]) * np.deg2rad(10.0))
        start[:3, :3] = (tilt * Rotation.from_rotvec([0.0, np.pi, 0.0])).as_matrix()
        fit = refit(InstrumentFit(initial_vector(start), np.ones(3), CAMERA_AND_TAPE), commands[train], pixels)
        positions.append(fit.theta[3:6])
    assert np.linalg.norm(positions[0] - positions[1]) < 0.005


def test_a_fit_turns_the_start_camera_and_frees_its_rotation_whole_only(rows):
    X, _, commands = rows
    theta = _identified_vector()
    fit = InstrumentFit(theta, np.ones(3), CAMERA_AND_TAPE)
    np.testing.assert_array_equal(theta_of(theta[list(CAMERA_AND_TAPE)] * np.r_[0, 0, 0, np.ones(7)], fit)[3:], theta[3:])
    np.testing.assert_allclose(theta_of(np.r_[0.0, 0.0, 0.0, theta[3:10]], fit), theta, atol=1e-12)
    np.testing.assert_allclose(theta_of(start_values(fit), fit), theta, atol=1e-12)  # a fit starts where it stands
    with pytest.raises(ValueError, match="whole"):
        start_values(InstrumentFit(theta, np.ones(3), (1, 2, 5)))
    with pytest.raises(ValueError, match="whole"):
        refit(InstrumentFit(theta, np.ones(3), (0, 1)), commands[:20], real_pixels(X)[:20])


def test_huber_residuals_square_to_scipys_huber_loss():
    from scipy.optimize import least_squares

    r = np.array([-9.0, -2.5, -2.0, -0.3, 0.0, 1.0, 2.0, 4.0, 50.0])
    for values in (r, r[[3, 5]], r[[0, 8]]):
        scipy_cost = least_squares(lambda x, v=values: v + 0.0 * x[0], [0.0], loss="huber", f_scale=HUBER_SCALE, max_nfev=1).cost
        assert 0.5 * np.sum(huber_residuals(values) ** 2) == pytest.approx(scipy_cost, rel=1e-12)
    np.testing.assert_array_equal(np.sign(huber_residuals(r)), np.sign(r))
    # Slope 1 up to the scale and on through it (continuous), 1 / sqrt(2 |r| / c - 1) beyond.
    for at, slope in ((0.0, 1.0), (HUBER_SCALE, 1.0), (-HUBER_SCALE, 1.0), (4.0, 1 / np.sqrt(2 * 4.0 / HUBER_SCALE - 1))):
        step = 1e-6
        assert (huber_residuals(np.array([at + step])) - huber_residuals(np.array([at - step])))[0] / (2 * step) == pytest.approx(
            slope, rel=1e-4
        )
    np.testing.assert_array_equal(huber_residuals(r[np.abs(r) <= HUBER_SCALE]), r[np.abs(r) <= HUBER_SCALE])


@pytest.mark.parametrize("name", ["homing_roll", "backlash_wrist"])
def test_a_refit_minimises_the_huber_pixel_loss_with_gaussian_priors(rows, name):
    # The identified roll offset lies about 6 prior sds out and the wrist backlash about 3.5:
    # where a Huber loss on the prior terms would have counted them linearly.
    X, _, commands = rows
    train, _ = split(len(X))
    pixels = real_pixels(X)[train]
    theta, i = _identified_vector(), PARAMETER_NAMES.index(name)
    scales = residual_rms(theta, commands[train], pixels)
    fit = refit(InstrumentFit(theta, scales, (i,)), commands[train], pixels)
    sd = PARAMETERS[i].prior_sd
    assert abs(fit.theta[i] / sd) > HUBER_SCALE

    def objective(value: float) -> float:
        candidate = theta.copy()
        candidate[i] = value
        scaled = ((predict_pixels(candidate, commands[train]) - pixels) / scales).ravel()
        return float(np.sum(huber_residuals(scaled) ** 2) + np.sum(prior_residuals(candidate, (i,)) ** 2))

    best = objective(fit.theta[i])
    assert objective(fit.theta[i] - 0.02 * sd) > best and objective(fit.theta[i] + 0.02 * sd) > best


def test_the_detectors_image_plane_noise_takes_the_stereo_depths_share():
    # Linearised, for a point (x, y, z) in the left camera frame and a per-pixel error s
    # (each camera, each axis; whole pixels add 1/12 px^2): x = (u_l - cx) b / d with
    # d = u_l - u_r, so var x = (z s / f)^2 ((1 - x / b)^2 + (x / b)^2), and
    # var y = (z s / f)^2 (1 + 2 (y / b)^2). Off the axis the depth's share dominates.
    noise = DetectionNoise(core_px=1.5, outlier_px=0.0, outlier_probability=0.0)
    point = np.array([[0.02, -0.012, 0.19]])
    x, y, z = point[0]
    b, s2 = paper.ENDOSCOPE_BASELINE_M, 1.5**2 + 1 / 12
    var_x = (z / paper.ENDOSCOPE_FOCAL_PX) ** 2 * s2 * ((1 - x / b) ** 2 + (x / b) ** 2)
    var_y = (z / paper.ENDOSCOPE_FOCAL_PX) ** 2 * s2 * (1 + 2 * (y / b) ** 2)
    expected_mm = np.sqrt((var_x + var_y) / 2) * 1e3
    assert detector_noise.plane_noise_mm(noise, point, draws=20_000, seed=1) == pytest.approx(expected_mm, rel=0.05)
    pixel_only_mm = z / paper.ENDOSCOPE_FOCAL_PX * np.sqrt(s2) * 1e3
    assert expected_mm > 3 * pixel_only_mm
    on_axis = detector_noise.plane_noise_mm(noise, np.array([[0.0, 0.0, 0.19]]), draws=20_000, seed=1)
    assert on_axis == pytest.approx(pixel_only_mm, rel=0.05)
    with pytest.raises(ValueError, match="non-positive disparity"):  # 6 m away: a disparity of 2 px, and 3 px of noise
        detector_noise.plane_noise_mm(DetectionNoise(core_px=3.0, outlier_px=0.0, outlier_probability=0.0), np.array([[0.0, 0.0, 6.0]]))


@pytest.mark.parametrize(
    ("points", "draws"),
    [
        (np.zeros((0, 3)), 16),
        (np.ones((4, 2)), 16),
        (np.array([[0.0, 0.0, -0.1]]), 16),
        (np.array([[np.nan, 0, 0.2]]), 16),
        (np.ones((2, 3)), 1),
        (np.ones((2, 3)), 100_001),
        (np.ones((1001, 3)), 10_000),
    ],
)
def test_the_detectors_image_plane_noise_refuses_bad_points_and_draws(points, draws):
    with pytest.raises(ValueError):
        detector_noise.plane_noise_mm(IDENTIFIED_MARKER_NOISE, points, draws=draws)


def test_repeatability_takes_what_the_model_and_detector_leave_of_the_jitter():
    assert repeatability_from_jitter(1.0, 0.6, 0.0) == pytest.approx(0.8e-3 * np.sqrt(2))
    assert repeatability_from_jitter(0.5, 0.6, 0.1) == 0.0


def test_the_settle_lag_is_where_the_share_first_falls_to_the_real_one_between_the_grids_lags():
    lags = (0.1, 0.2, 0.3)
    assert first_crossing(lags, (0.09, 0.03, 0.02), 0.0304) == 0.2  # 0.1993, to 0.01
    assert first_crossing(lags, (0.09, 0.05, 0.03), 0.04) == 0.25  # halfway between 0.2 and 0.3
    assert first_crossing(lags, (0.09, 0.04, 0.0304), 0.0304) == 0.3  # at most the target
    assert first_crossing(lags, (0.01, 0.04, 0.02), 0.0304) == 0.1  # the first, not the closest
    # A detector searching the whole image (benchmarks/identify_instrument.py before the search
    # boxes): 0.0306 at 0.20 is a hair over the real 0.0304, so the crossing lies just past 0.20,
    # not at 0.25 as the first grid point under the target would have it.
    assert first_crossing((0.15, 0.20, 0.25), (0.0455, 0.0306, 0.0223), 0.0304) == 0.2
    # With the boxes (identified.WRIST_SETTLE_LAG): 0.0461 at 0.15, 0.0257 at 0.20.
    assert first_crossing((0.15, 0.20, 0.25), (0.0461, 0.0257, 0.0249), 0.0304) == 0.19
    # Rounded to 0.01, never outside the two lags around the crossing.
    assert first_crossing((0.101, 0.102), (0.05, 0.01), 0.0499) == 0.101
    with pytest.raises(ValueError, match="extend the grid"):
        first_crossing(lags, (0.09, 0.05, 0.04), 0.0304)
    with pytest.raises(ValueError, match="increase"):
        first_crossing((0.2, 0.1, 0.3), (0.09, 0.03, 0.02), 0.0304)
    with pytest.raises(ValueError, match="one share per lag"):
        first_crossing(lags, (0.09, 0.03), 0.0304)


def test_settle_lag_match_collects_at_each_lag_and_a_larger_lag_reports_fewer_repeats():
    # Two short collections: without a lag the paused positions repeat; with a large one
    # the lagging wrist moves the reported tip between the rows of one pause.
    match = match_settle_lag(lags=(0.0, 0.6), n_trajectories=3)
    assert match.lags == (0.0, 0.6) and len(match.sim_shares) == len(match.sim_pitch_autocorrelations) == 2
    assert match.real_share == pytest.approx(0.0304, abs=5e-4)
    assert match.sim_shares[0] > 0.2 > match.sim_shares[1]
    above, below = match.sim_shares
    expected = round(0.6 * (above - match.real_share) / (above - below), 2)
    assert match.wrist_settle_lag == pytest.approx(expected) and 0.0 < expected <= 0.6


def test_the_identified_lag_is_the_paper_presets_and_within_the_grid():
    from dvrk_gym.fidelity.settle_lag import SETTLE_LAG_GRID
    from dvrk_gym.sim.robot.bias import BIAS_PRESETS

    assert BIAS_PRESETS["paper"].wrist_settle_lag == identified.WRIST_SETTLE_LAG
    assert SETTLE_LAG_GRID[0] <= identified.WRIST_SETTLE_LAG <= SETTLE_LAG_GRID[-1]
