"""Bring your own calibrator: the two-phase calibrator adds the paper's residual forests to any Phase I regressor."""

import numpy as np
import pytest
from sklearn.linear_model import LinearRegression
from sklearn.neighbors import KNeighborsRegressor

from dvrk_gym.calibration.models.forests import ResidualForests
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator


@pytest.fixture
def rows():
    rng = np.random.default_rng(0)
    position = np.column_stack([rng.uniform(-0.03, 0.03, (300, 2)), rng.uniform(0.17, 0.2, 300)])
    yaw = rng.choice(np.deg2rad([-90, -45, 0, 45, 90]), 300)
    X = np.column_stack([position, yaw, rng.uniform(-0.2, 0.4, 300), rng.uniform(-3.1, -2.6, 300)])
    bias = np.where(X[:, 3:4] > 0, 0.002, -0.001)  # a yaw-dependent offset a linear model of position misses
    y = X[:, :3] @ np.diag([1.0, -1.0, -1.0]) + bias
    return X, y


def test_a_scikit_learn_phase1_model_gets_the_forests_and_they_remove_its_yaw_error(rows):
    X, y = rows
    mine = LinearRegression().fit(X[:, :3], y)
    wrapped = _PositionOnly(mine)
    model = TwoPhaseCalibrator(dnn=wrapped, forests=ResidualForests(trees=20, seed=0)).fit_phase2(X, y)
    phase1_error = np.linalg.norm(wrapped.predict(X) - y, axis=1).mean()
    two_phase_error = np.linalg.norm(model.predict(X) - y, axis=1).mean()
    assert two_phase_error < 0.3 * phase1_error


def test_an_unfitted_scikit_learn_model_is_fitted_by_fit_phase1(rows):
    X, y = rows
    model = TwoPhaseCalibrator(dnn=KNeighborsRegressor(3), forests=ResidualForests(trees=5, seed=0))
    model.fit_phase1(X, y).fit_phase2(X, y)
    assert model.predict(X).shape == (300, 3)


def test_an_unfitted_model_of_ones_own_taken_as_fitted_says_to_call_fit_phase1(rows):
    """A model wrapping a scikit-learn one has no fitted attribute of its own to ask, so it is
    taken as fitted; its predict then failed deep inside scikit-learn (NotFittedError)."""
    X, y = rows

    class Wrapper:
        def __init__(self):
            self.model = KNeighborsRegressor(3)

        def fit(self, X, y):
            self.model.fit(X, y)
            return self

        def predict(self, X):
            return self.model.predict(X)

    with pytest.raises(ValueError, match=r"Phase I model Wrapper could not predict \(NotFittedError.*call fit_phase1 first"):
        TwoPhaseCalibrator(dnn=Wrapper(), forests=ResidualForests(trees=2)).fit_phase2(X, y)
    model = TwoPhaseCalibrator(dnn=Wrapper(), forests=ResidualForests(trees=2)).fit_phase1(X, y).fit_phase2(X, y)
    assert model.predict(X).shape == (300, 3)


def test_fit_of_the_two_phase_calibrator_warns_that_it_fits_phase1_only(rows):
    """make_calibrator("dnn+rf").fit(X, y) scored the network alone under the DNN+RF label."""
    X, y = rows
    model = TwoPhaseCalibrator(dnn=KNeighborsRegressor(3), forests=ResidualForests(trees=2))
    with pytest.warns(UserWarning, match="fits Phase I .* only"):
        model.fit(X, y)
    assert model.phase1_fitted_ and not model.phase2_fitted_


def test_a_phase1_model_returning_the_wrong_shape_is_named(rows):
    X, y = rows

    class Broken:
        def fit(self, X, y):
            return self

        def predict(self, X):
            return np.zeros((len(X), 2))

    with pytest.raises(ValueError, match=r"Broken\.predict\(X\)"):
        TwoPhaseCalibrator(dnn=Broken()).fit_phase2(X, y)


def test_saving_a_foreign_phase1_model_is_refused_with_what_to_do(rows, tmp_path):
    X, y = rows
    model = TwoPhaseCalibrator(dnn=_PositionOnly(LinearRegression().fit(X[:, :3], y)), forests=ResidualForests(trees=2)).fit_phase2(X, y)
    with pytest.raises(TypeError, match=r"model\.forests\.save"):
        model.save(tmp_path / "model.zip")
    assert not (tmp_path / "model.zip").exists()


class _PositionOnly:
    """A user's model: scikit-learn's regressor on the position columns (no fitted attributes of its own)."""

    def __init__(self, model):
        self.model = model

    def fit(self, X, y):
        self.model.fit(X[:, :3], y)
        return self

    def predict(self, X):
        return self.model.predict(X[:, :3])


def test_fitted_forests_passed_in_are_used_as_the_readme_saves_and_loads_them(rows, tmp_path):
    """``mine_rf.forests.save(path)`` then ``TwoPhaseCalibrator(dnn=mine, forests=ResidualForests.load(path))``
    predicted Phase I alone (2.7 mm off instead of 1.4 in the review's run), silently."""
    X, y = rows
    mine = _PositionOnly(LinearRegression().fit(X[:, :3], y))
    fitted = TwoPhaseCalibrator(dnn=mine, forests=ResidualForests(trees=5, seed=0)).fit_phase2(X, y)
    path = tmp_path / "forests.zip"
    fitted.forests.save(path)
    rebuilt = TwoPhaseCalibrator(dnn=mine, forests=ResidualForests.load(path))
    assert rebuilt.phase2_fitted_
    np.testing.assert_array_equal(rebuilt.predict(X), fitted.predict(X))
    assert not TwoPhaseCalibrator(dnn=mine, forests=ResidualForests(trees=5)).phase2_fitted_  # unfitted ones wait for fit_phase2


def test_an_unfitted_scikit_learn_estimator_is_not_taken_for_a_fitted_one(rows):
    from sklearn.ensemble import GradientBoostingRegressor
    from sklearn.multioutput import MultiOutputRegressor

    X, y = rows
    model = TwoPhaseCalibrator(dnn=MultiOutputRegressor(GradientBoostingRegressor(n_estimators=5)))
    with pytest.raises(ValueError, match="fit_phase2 called before fit_phase1"):  # was scikit-learn's NotFittedError, later
        model.fit_phase2(X, y)
    assert TwoPhaseCalibrator(dnn=MultiOutputRegressor(GradientBoostingRegressor(n_estimators=5)).fit(X, y)).phase1_fitted_


def test_a_users_own_estimator_on_scikit_learns_base_is_taken_as_fitted(rows):
    from sklearn.base import BaseEstimator, RegressorMixin

    class Mine(RegressorMixin, BaseEstimator):  # stores nothing ending in "_"
        def fit(self, X, y):
            return self

        def predict(self, X):
            return np.asarray(X)[:, :3]

    X, _ = rows
    model = TwoPhaseCalibrator(dnn=Mine())
    assert model.phase1_fitted_
    np.testing.assert_array_equal(model.predict(X), X[:, :3])
