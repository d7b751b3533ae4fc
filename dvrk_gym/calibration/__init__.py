"""Calibration: the paper's models (rigid body, DNN, per-yaw residual forests, two-phase),
baselines for the model search, the authors' data, and model files without pickle.

The names below are imported lazily (PEP 562), so importing a light submodule such as
``dvrk_gym.calibration.models.features`` does not pull in torch, scikit-learn and matplotlib.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "load_paper_phase1": "datasets",
    "DNNCalibrator": "models.dnn",
    "encode_euler": "models.features",
    "encode_quaternion": "models.features",
    "nearest_yaw_index": "models.features",
    "ForestCalibrator": "models.forests",
    "ResidualForests": "models.forests",
    "LinearCalibrator": "models.linear",
    "RigidBodyCalibrator": "models.rigid",
    "SearchResult": "search",
    "cross_validate": "search",
    "format_table": "search",
    "paper_models": "search",
    "plot_search": "search",
    "run_search": "search",
    "ModelFileError": "models.serialization",
    "TwoPhaseCalibrator": "models.two_phase",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
