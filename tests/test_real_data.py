"""Calibration models on the authors' real Phase I data (1939 rows), by 10-fold CV.

The authors report 10-fold CV errors of 3.76 mm^2 (linear), about 1.74 mm^2 (their 3 x 300
ReLU net in their code) and 2.06 mm^2 (the paper's chosen net).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.linear_model import LinearRegression

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.linear import LinearCalibrator
from dvrk_gym.calibration.search import (
    cross_validate,
    format_table,
    paper_models,
    plot_search,
    run_search,
)
from dvrk_gym.cli.main import main
from dvrk_gym.paper import AUTHORS_CV_MM2, REAL_PHASE1_ROWS

CHOSEN_NET_MAX_MM2 = 2.2
LINEAR_RANGE_MM2 = (3.4, 4.0)
# The net's CV test trains TEST_EPOCHS instead of the paper's 1000 so that it takes under
# two minutes on one core; benchmarks/bench_models.py reports the 1000-epoch figure.
TEST_EPOCHS = 150


@pytest.fixture(scope="module")
def paper_data() -> tuple[np.ndarray, np.ndarray]:
    return load_paper_phase1()


def test_paper_data_loads_in_si_units(paper_data) -> None:
    X, y = paper_data
    assert X.shape == (REAL_PHASE1_ROWS, 6) and y.shape == (REAL_PHASE1_ROWS, 3)
    assert X.dtype == np.float64 and y.dtype == np.float64
    # Camera depth 165-221 mm, yaw within +-91 deg, roll wrapping at +-180 deg, workspace
    # bx 5-71 mm, by 10-74 mm, bz -171 to -158 mm (DESIGN.md).
    assert X[:, 2].min() > 0.165 and X[:, 2].max() < 0.221
    assert np.abs(X[:, 3]).max() < np.radians(91.0)
    assert np.abs(X[:, 5]).max() <= np.pi and X[:, 5].max() > np.radians(170.0)
    np.testing.assert_array_less([0.005, 0.010, -0.171], y.min(axis=0))
    np.testing.assert_array_less(y.max(axis=0), [0.071, 0.074, -0.158])


def test_linear_regression_cv_error_matches_the_authors(paper_data) -> None:
    X, y = paper_data
    errors = cross_validate(lambda seed: LinearCalibrator(angles="euler"), X, y, folds=10)
    assert LINEAR_RANGE_MM2[0] <= np.mean(errors) <= LINEAR_RANGE_MM2[1]


def test_contiguous_folds_give_back_the_authors_linear_figure(paper_data) -> None:
    """Their code: scikit-learn's LinearRegression on the six raw columns, KFold(10) unshuffled."""
    X, y = paper_data
    errors = cross_validate(lambda seed: LinearRegression(), X, y, folds=10, shuffle=False)
    assert round(float(np.mean(errors)), 2) == AUTHORS_CV_MM2["linear"]
    shuffled = cross_validate(lambda seed: LinearRegression(), X, y, folds=10, shuffle=True)
    assert np.mean(shuffled) < np.mean(errors) - 0.1  # random folds leave neighbours on both sides


class _RecordingModel:
    """A model that remembers which rows it was asked to predict (by their first column, in mm)."""

    tested: list[np.ndarray] = []

    def fit(self, X: np.ndarray, y: np.ndarray) -> _RecordingModel:
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        _RecordingModel.tested.append(np.round(X[:, 0] * 1e3).astype(int))
        return np.zeros((len(X), 3))


def test_contiguous_folds_are_blocks_of_rows_in_order() -> None:
    X = np.column_stack([np.arange(25.0) * 1e-3, np.zeros((25, 5))])  # metres, in row order
    _RecordingModel.tested = []
    cross_validate(lambda seed: _RecordingModel(), X, np.zeros((25, 3)), folds=5, shuffle=False)
    assert [list(rows) for rows in _RecordingModel.tested] == [list(range(5 * k, 5 * k + 5)) for k in range(5)]
    _RecordingModel.tested = []
    cross_validate(lambda seed: _RecordingModel(), X, np.zeros((25, 3)), folds=5, shuffle=True)
    assert np.concatenate(_RecordingModel.tested).tolist() != list(range(25))


def test_quaternion_linear_regression_is_no_worse_than_euler(paper_data) -> None:
    X, y = paper_data
    euler = np.mean(cross_validate(lambda seed: LinearCalibrator("euler"), X, y, folds=10))
    quaternion = np.mean(cross_validate(lambda seed: LinearCalibrator("quaternion"), X, y, folds=10))
    assert quaternion <= euler


@pytest.mark.slow
@pytest.mark.paper_budget
def test_chosen_net_cv_error_is_within_the_paper_figure(paper_data) -> None:
    X, y = paper_data
    errors = cross_validate(lambda seed: DNNCalibrator(epochs=TEST_EPOCHS, seed=seed, progress=False), X, y, folds=10)
    assert np.mean(errors) <= CHOSEN_NET_MAX_MM2


@pytest.mark.slow
def test_quick_search_cross_validates_each_model_and_plots(paper_data, tmp_path) -> None:
    X, y = paper_data
    results = run_search(X, y, quick=True, progress=False)
    names = [result.name for result in results]
    assert names == [spec.name for spec in paper_models(quick=True)]
    table = format_table(results)
    assert "3-fold CV (shuffled folds)" in table and "Lin_EA" in table
    assert all(len(result.fold_mm2) == 3 for result in results)
    plot_search(results, str(tmp_path / "search.png"))
    assert (tmp_path / "search.png").stat().st_size > 10_000


@pytest.mark.slow
def test_search_command_uses_the_authors_contiguous_folds_on_their_data(tmp_path, capsys) -> None:
    assert main(["search", "--quick", "--out", str(tmp_path)]) == 0
    assert "3-fold CV (contiguous folds)" in capsys.readouterr().out
    rows = json.loads((tmp_path / "model_search.json").read_text())
    assert {row["split"] for row in rows} == {"contiguous"}
    linear = next(row for row in rows if row["name"] == "Lin_EA")
    X, y = load_paper_phase1()
    assert linear["folds_mm2"] == cross_validate(lambda seed: LinearCalibrator("euler"), X, y, folds=3, shuffle=False)
