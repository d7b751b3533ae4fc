"""Linear least-squares calibration: the model search's ``Lin_EA`` and ``Lin_Q``."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from sklearn.linear_model import LinearRegression

from dvrk_gym.calibration.models.features import check_inputs, check_targets, encode_euler, encode_quaternion
from dvrk_gym.calibration.models.serialization import SavableModel, require_array, require_names
from dvrk_gym.utils.checks import check_choice

__all__ = ["LinearCalibrator"]

_ENCODINGS: dict[str, tuple[Callable[[np.ndarray], np.ndarray], int]] = {
    "euler": (encode_euler, 9),
    "quaternion": (encode_quaternion, 7),
}


class LinearCalibrator(SavableModel):
    """Base position as an affine function of the encoded inputs, fitted by least squares.

    Args:
        angles: ``"euler"``: position plus sine and cosine of yaw, pitch, roll (the paper's
            Euler-angle inputs, without roll's wrap at +-pi); ``"quaternion"``: position plus
            the orientation's unit quaternion.
    """

    KIND = "linear_calibrator"

    def __init__(self, angles: str = "euler") -> None:
        self.angles = check_choice("angles", angles, sorted(_ENCODINGS))
        self.coef_: np.ndarray | None = None
        self.intercept_: np.ndarray | None = None

    def _encode(self, X: np.ndarray) -> np.ndarray:
        return _ENCODINGS[self.angles][0](X)

    def fit(self, X: np.ndarray, y: np.ndarray) -> LinearCalibrator:
        """Fit on inputs X (N, 6: metres, radians) and base positions y (N, 3, metres)."""
        X = check_inputs(X)
        y = check_targets(y, X.shape[0])
        regression = LinearRegression().fit(self._encode(X), y)
        self.coef_ = np.asarray(regression.coef_, dtype=np.float64)  # (3, features)
        self.intercept_ = np.asarray(regression.intercept_, dtype=np.float64)  # (3,)
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Base positions (N, 3) in metres for inputs X (N, 6: metres, radians)."""
        if self.coef_ is None or self.intercept_ is None:
            raise ValueError("LinearCalibrator.predict called before fit")
        return self._encode(check_inputs(X)) @ self.coef_.T + self.intercept_

    def _export(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        if self.coef_ is None or self.intercept_ is None:
            raise ValueError("LinearCalibrator.save called before fit")
        return {"angles": self.angles}, {"coef": self.coef_, "intercept": self.intercept_}

    @classmethod
    def _restore(cls, params: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> LinearCalibrator:
        model = cls(angles=params["angles"])
        require_names(arrays, {"coef", "intercept"})
        features = _ENCODINGS[model.angles][1]
        model.coef_ = require_array(arrays, "coef", (3, features), np.float64)
        model.intercept_ = require_array(arrays, "intercept", (3,), np.float64)
        return model
