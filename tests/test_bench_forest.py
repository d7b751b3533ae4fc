"""benchmarks/fidelity_forest.py: the helpers that take the forest's CV apart, on rows whose
answer is known, and the real rows' yaw terms and plane."""

import numpy as np
import pytest
from benchmark_scripts import load_script
from sklearn.linear_model import LinearRegression

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity.statistics import plane_slope

forest = load_script("fidelity_forest")


def _rows(rows: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Rows seen through a camera turned 30 degrees about x, with a point 3 mm off the
    reported one that turns with the yaw (m and rad)."""
    rng = np.random.default_rng(seed)
    y = np.column_stack([rng.uniform(0.0, 0.06, rows), rng.uniform(0.0, 0.06, rows), rng.uniform(-0.165, -0.160, rows)])
    yaw = rng.uniform(-np.pi / 2, np.pi / 2, rows)
    turn = np.deg2rad(30.0)
    rotation = np.array([[1, 0, 0], [0, np.cos(turn), -np.sin(turn)], [0, np.sin(turn), np.cos(turn)]])
    seen = y + 0.003 * np.column_stack([np.cos(yaw), np.sin(yaw), np.zeros(rows)])
    X = np.column_stack([seen @ rotation.T, yaw, rng.uniform(-0.2, 0.3, rows), rng.uniform(-3.1, -2.6, rows)])
    return X, y


def test_yaw_terms_give_back_the_offset_that_turns_with_the_yaw():
    X, y = _rows()
    # the camera sees y + 3 mm (cos, sin): the base position is the seen one minus it
    np.testing.assert_allclose(forest.yaw_terms(X, y), [[-0.003, 0.0], [0.0, -0.003], [0.0, 0.0]], atol=1e-9)


def test_tilting_moves_heights_to_the_slope_and_the_camera_with_them():
    X, y = _rows()
    X_tilted, y_tilted = forest.tilted_like(X, y, (-0.126, 0.009))
    assert plane_slope(y_tilted) == pytest.approx((-0.126, 0.009), abs=1e-9)
    np.testing.assert_array_equal(y_tilted[:, :2], y[:, :2])
    np.testing.assert_array_equal(X_tilted[:, 3:], X[:, 3:])
    # the camera positions moved as far as the heights, along the camera's view of base z
    lift = y_tilted[:, 2] - y[:, 2]
    moved = X_tilted[:, :3] - X[:, :3]
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), np.abs(lift), rtol=1e-6)
    turn = np.deg2rad(30.0)
    np.testing.assert_allclose(moved[np.argmax(lift)] / lift.max(), [0.0, -np.sin(turn), np.cos(turn)], atol=0.02)


def test_held_out_errors_are_zero_for_a_linear_map_and_distances_are_to_other_folds():
    X, _ = _rows(rows=200)
    y = X @ np.random.default_rng(1).normal(scale=0.01, size=(6, 3))
    errors, distance = forest.held_out_errors(LinearRegression, X, y)
    assert errors.shape == (200, 3) and errors.max() < 1e-20
    assert (distance > 0).all() and distance.max() < 0.02


def test_the_real_rows_turn_little_with_the_yaw():
    X, y = load_paper_phase1()
    terms = 1e3 * forest.yaw_terms(X, y)
    assert abs(terms[0, 1]) < 0.6 and abs(terms[1, 0]) < 0.2  # the simulated rows: 2.5 and 1.1 mm
