"""The paper's two-phase calibration: a DNN (Phase I) plus per-yaw residual forests (Phase II).

    x_b = f_DNN(x_c, phi) + f_RF^(yaw)(f_DNN(x_c, phi))

The Phase I model may be any regressor with scikit-learn's ``fit(X, y)`` / ``predict(X)``
(SI arrays: X (N, 6) metres and radians, y (N, 3) metres): the paper's DNN by default, or a
gradient-boosting model, a k-NN... of the user's, to which Phase II then adds the forests.

Phase I fits the network on the coarse exploration data; Phase II moves the gripper to known
targets via the network, records where a human (or a simulated one) pushed it, and fits one
forest per yaw to the residual between that corrected position and the network's prediction.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError
from sklearn.utils.validation import check_is_fitted

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.features import calibrator_layout, check_inputs, check_targets
from dvrk_gym.calibration.models.forests import FOREST_TYPES, ResidualForests
from dvrk_gym.calibration.models.serialization import ModelParts, SavableModel
from dvrk_gym.utils.checks import check_int

__all__ = ["TwoPhaseCalibrator"]

_DNN_PREFIX = "dnn."
_FORESTS_PREFIX = "rf."


class Regressor(Protocol):
    """What a Phase I model needs: scikit-learn's ``fit`` and ``predict``."""

    def fit(self, X: np.ndarray, y: np.ndarray) -> Any: ...

    def predict(self, X: np.ndarray) -> np.ndarray: ...


def _looks_fitted(model: Any) -> bool:
    """scikit-learn's convention: fitted attributes end in ``_``; one that is set means fitted.
    scikit-learn's own estimators are asked with its ``check_is_fitted`` (an unfitted
    ``MultiOutputRegressor`` has no such attribute at all). A model with none (a user's own
    class, built on scikit-learn's base or not) is taken as given: fitted.
    """
    if isinstance(model, BaseEstimator) and type(model).__module__.startswith("sklearn."):
        try:
            check_is_fitted(model)
        except NotFittedError:
            return False
        return True
    learned = [value for name, value in vars(model).items() if name.endswith("_") and not name.startswith("__")]
    return any(value is not None for value in learned) if learned else True


class TwoPhaseCalibrator(SavableModel):
    """A Phase I model plus per-yaw residual forests; with only Phase I fitted it equals that model.

    Args:
        dnn: The Phase I model: the paper's network by default (3 x 300 ReLU, 1000 epochs),
            or any regressor with ``fit``/``predict`` on SI arrays, fitted or not.
        forests: The Phase II residual forests (default: 100 trees, default depth); fitted
            ones (``ResidualForests.load``) are used as they are: they must have been fitted
            on the residuals of ``dnn``'s predictions.
        seed: Seed for the default components (ignored for components passed in).

    Example::

        from sklearn.ensemble import GradientBoostingRegressor
        from sklearn.multioutput import MultiOutputRegressor

        mine = MultiOutputRegressor(GradientBoostingRegressor()).fit(X1, y1)  # Phase I rows
        model = TwoPhaseCalibrator(dnn=mine).fit_phase2(X2, y2_corrected)  # adds the forests
    """

    KIND = "two_phase_calibrator"
    TRUSTED_TYPES = FOREST_TYPES

    def __init__(self, *, dnn: Regressor | None = None, forests: ResidualForests | None = None, seed: int = 0) -> None:
        check_int("seed", seed, 0, 2**32 - 1)  # the forests' (numpy's RandomState) bound
        if dnn is not None and not (callable(getattr(dnn, "fit", None)) and callable(getattr(dnn, "predict", None))):
            raise ValueError(f"dnn must be a regressor with fit and predict (or None for the paper's network), got {type(dnn).__name__}")
        if forests is not None and not isinstance(forests, ResidualForests):
            raise ValueError(f"forests must be ResidualForests (or None for the paper's), got {type(forests).__name__}")
        self.dnn: Regressor = dnn if dnn is not None else DNNCalibrator(seed=seed)
        self.forests = forests if forests is not None else ResidualForests(seed=seed)
        self.phase1_fitted_ = dnn is not None and _looks_fitted(dnn)
        self.phase2_fitted_ = forests is not None and forests.forests_ is not None  # fitted forests passed in are used

    def fit_phase1(self, X: np.ndarray, y: np.ndarray) -> TwoPhaseCalibrator:
        """Fit the network on Phase I inputs X (N, 6: m, rad) and base positions y (N, 3, m).

        Any Phase II fit is discarded, since its residuals were relative to the old network.
        """
        self.dnn.fit(X, y)
        self.phase1_fitted_ = True
        self.phase2_fitted_ = False
        return self

    def fit(self, X: np.ndarray, y: np.ndarray) -> TwoPhaseCalibrator:
        """:meth:`fit_phase1`, with a warning: the forests need the Phase II touches
        (:meth:`fit_phase2`), and until then the calibrator predicts as its Phase I model
        (``make_calibrator("dnn+rf").fit(X, y)`` alone would score the DNN as DNN+RF)."""
        self.fit_phase1(X, y)
        warnings.warn(
            "TwoPhaseCalibrator.fit(X, y) fits Phase I (the network) only; until fit_phase2 fits the residual forests on "
            "the Phase II touches, it predicts as the network",
            UserWarning,
            stacklevel=2,
        )
        return self

    def fit_phase2(self, X_c_phase2: np.ndarray, y_corrected: np.ndarray) -> TwoPhaseCalibrator:
        """Fit the residual forests on Phase II data.

        Args:
            X_c_phase2: (M, 6) inputs at the Phase II targets (camera position in metres,
                commanded yaw, pitch, roll in radians).
            y_corrected: (M, 3) base positions in metres after the human correction.

        Returns:
            self.

        Raises:
            ValueError: If Phase I is not fitted or the arrays are malformed.
        """
        X_c_phase2 = check_inputs(X_c_phase2, name="X_c_phase2")
        y_corrected = check_targets(y_corrected, X_c_phase2.shape[0], name="y_corrected")
        if not self.phase1_fitted_:
            raise ValueError("fit_phase2 called before fit_phase1")
        predicted = self._phase1_predict(X_c_phase2)
        self.forests.fit(predicted, X_c_phase2[:, 3], y_corrected - predicted)
        self.phase2_fitted_ = True
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Base positions (N, 3) in metres for inputs X (N, 6: metres, radians)."""
        if not self.phase1_fitted_:
            raise ValueError("TwoPhaseCalibrator.predict called before fit_phase1")
        X = check_inputs(X)
        base = self._phase1_predict(X)
        if self.phase2_fitted_:
            base = base + self.forests.predict(base, X[:, 3])
        return base

    def _phase1_predict(self, X: np.ndarray) -> np.ndarray:
        """The Phase I model's base positions (N, 3), m, checked: a user's model may return anything."""
        try:
            predicted = np.asarray(self.dnn.predict(X), dtype=float)
        except Exception as error:  # a user's model taken as fitted (it has no fitted attribute to ask) may not be
            raise ValueError(
                f"the Phase I model {type(self.dnn).__name__} could not predict ({type(error).__name__}: {str(error)[:200]}); "
                "if it is not fitted, call fit_phase1 first"
            ) from error
        return check_targets(predicted, X.shape[0], name=f"{type(self.dnn).__name__}.predict(X)")

    def layout(self) -> dict[str, Any]:
        """Inputs (m, rad), outputs (m), and the layouts of the network and of the residual forests."""
        return {**calibrator_layout(), "phase1": DNNCalibrator().layout(), "phase2": self.forests.layout()}

    def _export(self) -> ModelParts:
        if not isinstance(self.dnn, DNNCalibrator):
            raise TypeError(
                f"a model file holds the paper's DNN as Phase I, not a {type(self.dnn).__name__}: save the "
                "forests alone (model.forests.save(path)) and your Phase I model with its own library"
            )
        dnn = self.dnn._export().prefixed(_DNN_PREFIX)
        params: dict[str, Any] = {"dnn": dnn.params, "forests": None}
        if not self.phase2_fitted_:
            return ModelParts(params, dnn.arrays, dnn.estimators)
        forests = self.forests._export().prefixed(_FORESTS_PREFIX)
        params["forests"] = forests.params
        return ModelParts(params, {**dnn.arrays, **forests.arrays}, {**dnn.estimators, **forests.estimators})

    @classmethod
    def _from_params(cls, params: Mapping[str, Any]) -> TwoPhaseCalibrator:
        dnn = DNNCalibrator._from_params(params["dnn"])
        if params["forests"] is None:
            return cls(dnn=dnn)
        return cls(dnn=dnn, forests=ResidualForests._from_params(params["forests"]))

    def _load_parts(self, parts: ModelParts) -> None:
        unknown = sorted(name for name in [*parts.arrays, *parts.estimators] if not name.startswith((_DNN_PREFIX, _FORESTS_PREFIX)))
        if unknown:
            raise ValueError(f"unexpected arrays or estimators {unknown}")
        if not isinstance(self.dnn, DNNCalibrator):
            raise TypeError(f"a two-phase model file holds the paper's DNN; this calibrator's Phase I is a {type(self.dnn).__name__}")
        self.dnn._load_parts(parts.part(_DNN_PREFIX, parts.params["dnn"]))
        self.phase1_fitted_ = True
        forests = parts.part(_FORESTS_PREFIX, parts.params["forests"] or {})
        if parts.params["forests"] is None:
            if forests.arrays or forests.estimators:
                raise ValueError("forests present but the parameters say Phase II is not fitted")
            return
        self.forests._load_parts(forests)
        self.phase2_fitted_ = True
