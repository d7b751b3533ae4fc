"""Random-forest models: the Phase II residual forests and a Phase I forest baseline.

- :class:`ResidualForests` is the paper's Phase II: one forest (100 trees, default depth)
  per yaw in {-90, -45, 0, 45, 90} deg, mapping the DNN's predicted base position to the
  residual that the human correction revealed.
- :class:`ForestCalibrator` is the model search's ``RFs_tA_dB``: one forest from the
  calibration inputs to the base position.

Both predict with :class:`~dvrk_gym.calibration.models.tree_ensemble.TreeEnsemble`, so a fitted
and a loaded model run the same code and agree bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.models.features import (
    PAPER_YAWS_RAD,
    check_inputs,
    check_targets,
    encode_euler,
    nearest_yaw_index,
)
from dvrk_gym.calibration.models.serialization import SavableModel, require_names
from dvrk_gym.calibration.models.tree_ensemble import TreeEnsemble, fit_forest
from dvrk_gym.utils.checks import check_int

__all__ = ["ForestCalibrator", "ResidualForests"]

_EULER_FEATURES = 9
_POSITION_FEATURES = 3


MAX_TREES = 10_000
MAX_DEPTH = 1_000


def _check_forest_params(trees: int, max_depth: int | None, seed: int) -> None:
    check_int("trees", trees, 1, MAX_TREES)
    if max_depth is not None:
        check_int("max_depth (or None)", max_depth, 1, MAX_DEPTH)
    check_int("seed", seed, 0, 2**32 - 1)  # scikit-learn's random_state range


class ForestCalibrator(SavableModel):
    """Phase I baseline: a random forest from (position, angles) to base position.

    The inputs are encoded as position plus sine and cosine of each angle (trees need no
    scaling; the encoding only removes roll's wrap at +-pi).

    Args:
        trees: Number of trees.
        max_depth: Maximum tree depth; None grows each tree until its leaves are pure.
        seed: ``random_state`` of the forest.
    """

    KIND = "forest_calibrator"

    def __init__(self, trees: int = 100, max_depth: int | None = None, seed: int = 0) -> None:
        _check_forest_params(trees, max_depth, seed)
        self.trees = int(trees)
        self.max_depth = None if max_depth is None else int(max_depth)
        self.seed = int(seed)
        self.ensemble_: TreeEnsemble | None = None

    def fit(self, X: np.ndarray, y: np.ndarray) -> ForestCalibrator:
        """Fit on inputs X (N, 6: metres, radians) and base positions y (N, 3, metres)."""
        X = check_inputs(X)
        y = check_targets(y, X.shape[0])
        self.ensemble_ = fit_forest(encode_euler(X), y, self.trees, self.max_depth, self.seed)
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Base positions (N, 3) in metres for inputs X (N, 6: metres, radians)."""
        if self.ensemble_ is None:
            raise ValueError("ForestCalibrator.predict called before fit")
        return self.ensemble_.predict(encode_euler(check_inputs(X)))

    def _export(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        if self.ensemble_ is None:
            raise ValueError("ForestCalibrator.save called before fit")
        params = {"trees": self.trees, "max_depth": self.max_depth, "seed": self.seed}
        return params, self.ensemble_.to_arrays()

    @classmethod
    def _restore(cls, params: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> ForestCalibrator:
        model = cls(trees=params["trees"], max_depth=params["max_depth"], seed=params["seed"])
        require_names(arrays, TreeEnsemble.array_names())
        model.ensemble_ = TreeEnsemble.from_arrays(arrays, "", _EULER_FEATURES, 3)
        if model.ensemble_.n_trees != model.trees:
            raise ValueError(f"file holds {model.ensemble_.n_trees} trees; params say {model.trees}")
        return model


class ResidualForests(SavableModel):
    """Phase II: per-yaw random forests from predicted base position to its residual.

    Rows are grouped by the nearest of the paper's five yaws (wrapped distance). A group
    without training rows predicts a zero residual.

    Args:
        trees: Trees per forest (paper: 100).
        max_depth: Maximum depth (paper: None, sklearn's default).
        seed: ``random_state`` of every forest.
    """

    KIND = "residual_forests"

    def __init__(self, trees: int = paper.RESIDUAL_FOREST_TREES, max_depth: int | None = None, seed: int = 0) -> None:
        _check_forest_params(trees, max_depth, seed)
        self.trees = int(trees)
        self.max_depth = None if max_depth is None else int(max_depth)
        self.seed = int(seed)
        self.forests_: list[TreeEnsemble | None] | None = None

    def fit(self, predicted_base: np.ndarray, yaw: np.ndarray, residual: np.ndarray) -> ResidualForests:
        """Fit one forest per yaw group.

        Args:
            predicted_base: (N, 3) Phase I predictions of the base position, metres.
            yaw: (N,) yaw of each row in radians (grouped to the nearest paper yaw).
            residual: (N, 3) corrected minus predicted base position, metres.

        Returns:
            self.
        """
        predicted_base, groups = self._check(predicted_base, yaw)
        residual = check_targets(residual, predicted_base.shape[0], name="residual")
        self.forests_ = [
            fit_forest(predicted_base[groups == g], residual[groups == g], self.trees, self.max_depth, self.seed)
            if np.any(groups == g)
            else None
            for g in range(len(PAPER_YAWS_RAD))
        ]
        return self

    def predict(self, predicted_base: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        """Residual (N, 3, metres) at Phase I predictions (N, 3, metres) and yaws (N,, rad)."""
        if self.forests_ is None:
            raise ValueError("ResidualForests.predict called before fit")
        predicted_base, groups = self._check(predicted_base, yaw)
        residual = np.zeros_like(predicted_base)
        for g, forest in enumerate(self.forests_):
            rows = groups == g
            if forest is not None and np.any(rows):
                residual[rows] = forest.predict(predicted_base[rows])
        return residual

    @staticmethod
    def _check(predicted_base: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        predicted_base = check_inputs(predicted_base, name="predicted_base", columns=3)
        yaw = check_inputs(np.reshape(np.asarray(yaw, dtype=np.float64), (-1, 1)), "yaw", 1)[:, 0]
        if yaw.shape[0] != predicted_base.shape[0]:
            raise ValueError(f"yaw has {yaw.shape[0]} values but predicted_base has {predicted_base.shape[0]} rows")
        return predicted_base, nearest_yaw_index(yaw)

    def _export(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        if self.forests_ is None:
            raise ValueError("ResidualForests.save called before fit")
        fitted = {g: forest for g, forest in enumerate(self.forests_) if forest is not None}
        params = {"trees": self.trees, "max_depth": self.max_depth, "seed": self.seed, "groups": list(fitted)}
        arrays: dict[str, np.ndarray] = {}
        for g, forest in fitted.items():
            arrays.update(forest.to_arrays(f"yaw{g}_"))
        return params, arrays

    @classmethod
    def _restore(cls, params: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> ResidualForests:
        model = cls(trees=params["trees"], max_depth=params["max_depth"], seed=params["seed"])
        groups = params["groups"]
        if not isinstance(groups, list) or not set(groups) <= set(range(len(PAPER_YAWS_RAD))):
            raise ValueError(f"groups {groups!r}; expected a list of indices 0..4")
        require_names(arrays, set().union(*(TreeEnsemble.array_names(f"yaw{g}_") for g in groups)))
        model.forests_ = [
            TreeEnsemble.from_arrays(arrays, f"yaw{g}_", _POSITION_FEATURES, 3) if g in groups else None for g in range(len(PAPER_YAWS_RAD))
        ]
        for g, forest in enumerate(model.forests_):
            if forest is not None and forest.n_trees != model.trees:
                raise ValueError(f"yaw group {g} holds {forest.n_trees} trees; params say {model.trees}")
        return model
