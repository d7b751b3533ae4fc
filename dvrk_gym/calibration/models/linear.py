"""Linear least-squares calibration: the model search's ``Lin_EA`` and ``Lin_Q``."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from sklearn.linear_model import LinearRegression

from dvrk_gym.calibration.models.features import (
    EULER_FEATURES,
    QUATERNION_FEATURES,
    calibrator_layout,
    check_inputs,
    check_targets,
    encode_euler,
    encode_quaternion,
)
from dvrk_gym.calibration.models.serialization import ModelParts, SavableModel, require_array, require_names
from dvrk_gym.utils.checks import check_choice

__all__ = ["LinearCalibrator"]

_ENCODINGS: dict[str, tuple[Callable[[np.ndarray], np.ndarray], tuple[str, ...]]] = {
    "euler": (encode_euler, EULER_FEATURES),
    "quaternion": (encode_quaternion, QUATERNION_FEATURES),
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

    def layout(self) -> dict[str, Any]:
        """Inputs (m, rad), the encoded features, outputs (m)."""
        return calibrator_layout(_ENCODINGS[self.angles][1])

    def _export(self) -> ModelParts:
        if self.coef_ is None or self.intercept_ is None:
            raise ValueError("LinearCalibrator.save called before fit")
        return ModelParts({"angles": self.angles}, {"coef": self.coef_, "intercept": self.intercept_})

    @classmethod
    def _from_params(cls, params: Mapping[str, Any]) -> LinearCalibrator:
        require_names(params, {"angles"}, "parameters")
        return cls(angles=params["angles"])

    def _load_parts(self, parts: ModelParts) -> None:
        require_names(parts.estimators, set(), "estimators")
        require_names(parts.arrays, {"coef", "intercept"})
        self.coef_ = require_array(parts.arrays, "coef", (3, len(_ENCODINGS[self.angles][1])), np.float64)
        self.intercept_ = require_array(parts.arrays, "intercept", (3,), np.float64)
