"""The calibrators by name: build an untrained one from its name and hyper-parameters.

Names are those the command line and the paper use: ``"rbt"`` (rigid body per yaw),
``"linear"``, ``"forest"``, ``"dnn"`` (the paper's Phase I network) and ``"dnn+rf"`` (the
two-phase calibrator: the DNN plus per-yaw residual forests).
"""

from __future__ import annotations

from typing import Any

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.forests import ForestCalibrator
from dvrk_gym.calibration.models.linear import LinearCalibrator
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.models.serialization import SavableModel
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator

CALIBRATOR_CLASSES: dict[str, type[SavableModel]] = {
    "rbt": RigidBodyCalibrator,
    "linear": LinearCalibrator,
    "forest": ForestCalibrator,
    "dnn": DNNCalibrator,
    "dnn+rf": TwoPhaseCalibrator,
}
"""Each calibrator's class, by name."""


def make_calibrator(name: str, **params: Any) -> SavableModel:
    """An untrained calibrator, ready for ``fit(X, y)``; ``"dnn+rf"``'s fits its network only
    (with a warning): its residual forests need ``fit_phase2`` on the Phase II touches.

    Args:
        name: one of :data:`CALIBRATOR_CLASSES` (``"rbt"``, ``"linear"``, ``"forest"``,
            ``"dnn"``, ``"dnn+rf"``).
        **params: the class's own keyword arguments (for ``"dnn"``: ``hidden_layers``,
            ``units``, ``epochs``, ``seed``...).

    Raises:
        ValueError: an unknown name, or keyword arguments the class does not take.

    Example::

        model = make_calibrator("dnn", epochs=200, seed=0).fit(X, y)  # X: (n, 6), y: (n, 3) in metres, radians
    """
    try:
        cls = CALIBRATOR_CLASSES[name]
    except KeyError:
        raise ValueError(f"unknown calibrator {name!r}; expected one of {sorted(CALIBRATOR_CLASSES)}") from None
    try:
        return cls(**params)
    except TypeError as error:
        raise ValueError(f"bad parameters for calibrator {name!r} ({cls.__name__}): {error}") from error
