"""The fidelity statistics: the issue's real-robot column on the authors' rows, and axes and
units checked on synthetic rows whose answer is known."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity.comparison import compare
from dvrk_gym.fidelity.statistics import (
    PAPER_YAWS_DEG,
    SAME_POSITION_M,
    fidelity_statistics,
    lag_one_correlation,
    plane_slope,
    rigid_residuals_camera,
)


@pytest.mark.slow
def test_real_rows_give_the_issues_real_robot_column():
    stats = fidelity_statistics(*load_paper_phase1())
    assert stats.rows == 1939
    assert round(stats.rigid_residual_rms_mm, 1) == 6.6
    assert round(stats.view_axis_share, 2) == 0.89
    assert round(stats.view_axis_jitter_mm, 1) == 5.2
    assert round(stats.image_plane_jitter_mm, 1) == 1.0
    assert round(stats.same_position_share, 2) == 0.03
    assert round(stats.pitch_autocorrelation, 2) == 0.27
    assert round(stats.plane_tilt_deg, 1) == 7.2 and [round(a, 3) for a in stats.plane_slope] == [-0.126, 0.009]
    assert [round(f, 2) for f in stats.kept_fraction_per_yaw] == [0.13, 0.30, 0.28, 0.20, 0.09]
    assert (round(stats.pitch_p5_deg), round(stats.pitch_p95_deg)) == (-11, 21)
    assert [round(p, 1) for p in stats.pitch_median_per_yaw_deg] == [11.7, 7.6, -1.0, -3.0, -1.1]
    assert round(stats.cv_linear_mm2, 2) == 3.76
    assert round(stats.cv_forest_mm2, 1) == 5.0
    json.dumps(stats.to_dict())


def _synthetic_rows(noise_camera_m: np.ndarray, rows: int = 800, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 1-mm random walk in the base frame, seen through one rigid transform per paper yaw,
    with ``noise_camera_m`` (3,) the per-axis standard deviation of camera-frame noise, m."""
    rng = np.random.default_rng(seed)
    base = np.array([0.04, 0.04, -0.165]) + np.cumsum(rng.normal(scale=0.001, size=(rows, 3)), axis=0) * [1.0, 1.0, 0.2]
    yaw_deg = rng.choice(PAPER_YAWS_DEG, size=rows) + rng.uniform(-20, 20, size=rows)
    pitch_deg = rng.uniform(-15, 25, size=rows)
    roll_deg = rng.uniform(-180, -150, size=rows)
    # a camera tilted 35 deg from looking straight down, so camera z is not base -z
    rotations = Rotation.from_euler("xyz", rng.normal(scale=0.05, size=(5, 3)) + [np.pi - 0.6, 0.3, 0.5]).as_matrix()
    translations = base.mean(axis=0) - rotations @ [0.0, 0.0, 0.19] + rng.normal(scale=0.002, size=(5, 3))
    groups = np.argmin(np.abs(yaw_deg[:, None] - np.array(PAPER_YAWS_DEG)), axis=1)
    camera = np.einsum("nji,nj->ni", rotations[groups], base - translations[groups])
    camera += rng.normal(size=(rows, 3)) * noise_camera_m
    X = np.column_stack([camera, np.deg2rad(np.column_stack([yaw_deg, pitch_deg, roll_deg]))])
    return X, base


def test_noise_along_camera_z_only_is_all_view_axis():
    X, y = _synthetic_rows(np.array([0.0, 0.0, 0.005]))
    assert X[:, 2].min() > 0.15 and X[:, 2].max() < 0.25  # depth ~ 19 cm, as the real camera
    stats = fidelity_statistics(X, y, cross_validation=False)
    assert stats.view_axis_share > 0.99
    assert stats.view_axis_jitter_mm == pytest.approx(5.0, rel=0.1)
    assert stats.image_plane_jitter_mm < 0.3
    assert stats.rigid_residual_rms_mm == pytest.approx(5.0, rel=0.1)


def test_noise_along_camera_x_only_is_in_the_image_plane():
    X, y = _synthetic_rows(np.array([0.002, 0.0, 0.0]))
    stats = fidelity_statistics(X, y, cross_validation=False)
    assert stats.view_axis_share < 0.01
    assert stats.view_axis_jitter_mm < 0.1
    # pooled over camera x and y, a 2 mm noise on x alone is 2 / sqrt(2) mm per axis
    assert stats.image_plane_jitter_mm == pytest.approx(2.0 / np.sqrt(2.0), rel=0.1)


def test_residual_is_in_the_camera_frame_with_the_cameras_sign():
    X, y = _synthetic_rows(np.zeros(3))
    X[7, 2] += 0.003  # the marker seen 3 mm deeper than it is
    residual = rigid_residuals_camera(X, y)
    assert residual[7, 2] == pytest.approx(0.003, abs=2e-4)
    assert np.abs(residual[7, :2]).max() < 2e-4


def test_yaw_fractions_and_pitch_percentiles_are_in_the_reports_units():
    X, y = _synthetic_rows(np.full(3, 0.001))
    X[:, 3] = np.deg2rad(np.repeat([-90.0, -40.0, 5.0, 50.0, 85.0], [80, 160, 240, 240, 80]))
    X[:, 4] = np.deg2rad(np.linspace(-10.0, 20.0, len(X)))
    stats = fidelity_statistics(X, y, cross_validation=False)
    assert stats.kept_fraction_per_yaw == pytest.approx((0.1, 0.2, 0.3, 0.3, 0.1))
    assert stats.pitch_p5_deg == pytest.approx(-8.5, abs=0.05)
    assert stats.pitch_p95_deg == pytest.approx(18.5, abs=0.05)


def test_rows_on_a_plane_tilted_about_base_y_give_its_slope_and_angle():
    X, y = _synthetic_rows(np.full(3, 0.001))
    y[:, 2] = -0.16 + np.tan(np.deg2rad(-7.0)) * (y[:, 0] - 0.04) + 0.01 * (y[:, 1] - 0.04)
    stats = fidelity_statistics(X, y, cross_validation=False)
    assert stats.plane_slope == pytest.approx((np.tan(np.deg2rad(-7.0)), 0.01))
    assert stats.plane_tilt_deg == pytest.approx(np.rad2deg(np.arctan(np.hypot(np.tan(np.deg2rad(7.0)), 0.01))))
    y[:, 2] = -0.16  # level
    assert fidelity_statistics(X, y, cross_validation=False).plane_tilt_deg == pytest.approx(0.0, abs=1e-9)


def test_rows_near_one_line_give_no_tilt_and_fail_that_row_only():
    """A short collection can stay near one line seen from above: no plane, so the tilt is
    nan (null in the JSON) and its comparison row fails; the other statistics stand."""
    X, y = _synthetic_rows(np.full(3, 0.001))
    y[:, 1] = 0.04 + 0.001 * (y[:, 1] - y[:, 1].mean()) / np.ptp(y[:, 1])  # 1 mm wide across x's tens of mm
    stats = fidelity_statistics(X, y, cross_validation=False)
    assert np.isnan(stats.plane_tilt_deg) and np.isnan(stats.plane_slope).all()
    assert stats.to_dict()["plane_tilt_deg"] is None and stats.to_dict()["plane_slope"] == [None, None]
    assert np.isfinite(stats.rigid_residual_rms_mm) and np.isfinite(stats.view_axis_jitter_mm)
    rows = {row.name: row for row in compare(stats, stats, 0.37, 0.37)}
    assert not rows["tilt of the rows' plane in the base frame (deg)"].passed
    assert all(row.passed for name, row in rows.items() if not name.startswith("tilt"))


@pytest.mark.parametrize(
    ("positions", "message"),
    [
        (np.zeros((2, 3)), "N >= 3"),
        (np.zeros((5, 2)), "N >= 3"),
        (np.array([[0.0, 0.0, 0.0], [0.01, 0.01, 0.0], [np.nan, 0.0, 0.0]]), "finite"),
        (np.column_stack([np.linspace(0, 0.05, 6), np.linspace(0, 0.05, 6), np.zeros(6)]), "one line"),
        (np.full((4, 3), 0.01), "width across it is 0 of"),  # one point, four times
        # 0.1 mm either side of a 50 mm line: lstsq's rank is 3, but the tilt across the line would be noise
        (np.column_stack([np.linspace(0, 0.05, 6), [0.0, 1e-4, -1e-4] * 2, np.zeros(6)]), r"width across it is 0\.0046 of .* under 0\.05"),
    ],
)
def test_plane_slope_refuses_what_defines_no_plane(positions, message):
    with pytest.raises(ValueError, match=message):
        plane_slope(positions)


def test_plane_slope_fits_a_narrow_cloud_that_is_not_one_line():
    x = np.linspace(0.0, 0.05, 6)
    across = np.array([0.0, 0.004, -0.004] * 2)  # 4 mm either side of a 50 mm line: width 0.09 of length
    z = 0.1 * x - 0.2 * across + 0.3
    assert plane_slope(np.column_stack([x, across, z])) == pytest.approx((0.1, -0.2))


def test_cross_validation_of_an_exactly_linear_map_is_zero_for_the_linear_model():
    X, _ = _synthetic_rows(np.zeros(3), rows=300)
    y = X @ np.random.default_rng(1).normal(scale=0.01, size=(6, 3)) + [0.04, 0.04, -0.16]
    stats = fidelity_statistics(X, y)
    assert stats.cv_linear_mm2 < 1e-12
    assert stats.cv_forest_mm2 > 1e-3


@pytest.mark.parametrize(
    ("column", "scale", "message"),
    [(2, 1000.0, "expected metres"), (4, 180.0 / np.pi, "expected radians")],
)
def test_millimetres_or_degrees_are_refused(column, scale, message):
    X, y = _synthetic_rows(np.zeros(3), rows=50)
    X[:, column] *= scale
    with pytest.raises(ValueError, match=message):
        fidelity_statistics(X, y, cross_validation=False)


def test_lag_one_correlation_of_an_autoregressive_sequence_is_its_coefficient():
    rng = np.random.default_rng(3)
    values = np.zeros(20000)
    for i in range(1, values.size):
        values[i] = 0.6 * values[i - 1] + rng.normal()
    assert lag_one_correlation(values) == pytest.approx(0.6, abs=0.02)
    assert lag_one_correlation(rng.normal(size=20000)) == pytest.approx(0.0, abs=0.03)
    assert lag_one_correlation(np.full(10, 0.2)) == 0.0
    with pytest.raises(ValueError, match="at least 2"):
        lag_one_correlation(np.array([1.0]))


def test_rows_repeating_their_reported_position_count_as_same_position():
    X, y = _synthetic_rows(np.zeros(3), rows=400)
    assert fidelity_statistics(X, y, cross_validation=False).same_position_share < 0.02  # a 1 mm walk rarely stays put
    y[1::2] = y[0::2] + SAME_POSITION_M / 2  # every other row within the threshold of the one before
    stats = fidelity_statistics(X, y, cross_validation=False)
    assert 200 / 399 <= stats.same_position_share < 200 / 399 + 0.02
    X[:, 4] = np.repeat(X[0::2, 4], 2)  # pairs of rows share their pitch
    assert fidelity_statistics(X, y, cross_validation=False).pitch_autocorrelation > 0.4
