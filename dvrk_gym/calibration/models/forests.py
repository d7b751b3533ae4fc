"""Random-forest models: the Phase II residual forests and a Phase I forest baseline.

- :class:`ResidualForests` is the paper's Phase II: one forest (100 trees, default depth)
  per yaw in {-90, -45, 0, 45, 90} deg, mapping the DNN's predicted base position to the
  residual that the human correction revealed.
- :class:`ForestCalibrator` is the model search's ``RFs_tA_dB``: one forest from the
  calibration inputs to the base position.

The forests are scikit-learn's ``RandomForestRegressor``, saved through ``skops.io`` and read
back as only the types of :data:`FOREST_TYPES`; a loaded forest's trees are checked
(:func:`check_forest`) before scikit-learn, whose tree traversal follows child indices without
bounds checks, predicts with them. :func:`forest_predict` averages the trees' own predictions
in the forest's order, which is what ``RandomForestRegressor.predict`` computes (bit for bit),
without its per-call dispatch through joblib (about 10 ms a call, whatever the rows).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from sklearn.ensemble import RandomForestRegressor
from sklearn.tree import DecisionTreeRegressor
from sklearn.tree._tree import Tree  # the node arrays' class, named in FOREST_TYPES

from dvrk_gym import paper
from dvrk_gym.calibration.models.features import (
    EULER_FEATURES,
    PAPER_YAWS_RAD,
    calibrator_layout,
    check_inputs,
    check_targets,
    encode_euler,
    nearest_yaw_index,
)
from dvrk_gym.calibration.models.serialization import ModelParts, SavableModel, require_names
from dvrk_gym.utils.checks import check_int

__all__ = ["FOREST_TYPES", "ForestCalibrator", "ResidualForests", "check_forest", "fit_forest", "forest_predict"]

FOREST_TYPES = (
    "builtins.dict",
    "builtins.list",
    "builtins.str",
    "builtins.tuple",
    "numpy.ndarray",
    "sklearn.ensemble._forest.RandomForestRegressor",
    "sklearn.tree._classes.DecisionTreeRegressor",
    "sklearn.tree._tree.Tree",
)
"""Every type a saved forest may contain: the trusted-types list its skops file is read with."""
MAX_TREES = 10_000
MAX_DEPTH = 1_000
_TREE_LEAF = -1  # scikit-learn's child index of a leaf
_OUTPUTS = 3
_POSITION_FEATURES = ("predicted_bx_m", "predicted_by_m", "predicted_bz_m")


def _check_forest_params(trees: int, max_depth: int | None, seed: int) -> None:
    check_int("trees", trees, 1, MAX_TREES)
    if max_depth is not None:
        check_int("max_depth (or None)", max_depth, 1, MAX_DEPTH)
    check_int("seed", seed, 0, 2**32 - 1)  # scikit-learn's random_state range


def _unfitted(trees: int, max_depth: int | None, seed: int) -> RandomForestRegressor:
    return RandomForestRegressor(n_estimators=trees, max_depth=max_depth, random_state=seed)


def fit_forest(X: np.ndarray, y: np.ndarray, *, trees: int, max_depth: int | None, seed: int) -> RandomForestRegressor:
    """A seeded ``RandomForestRegressor`` fitted on features X (N, F) and targets y (N, K)."""
    return _unfitted(trees, max_depth, seed).fit(X, y)


def forest_predict(forest: RandomForestRegressor, X: np.ndarray) -> np.ndarray:
    """``forest.predict(X)``, bit for bit: the mean of the trees' predictions, summed in order.

    Args:
        forest: a fitted forest of ``n_features_in_`` features and ``n_outputs_`` > 1 outputs.
        X: (N, n_features_in_) finite features (compared in float32, as scikit-learn does).

    Returns:
        (N, n_outputs_) float64 predictions.
    """
    X = np.asarray(X)
    if X.ndim != 2 or X.shape[1] != forest.n_features_in_:
        raise ValueError(f"X has shape {X.shape}; the forest expects (N, {forest.n_features_in_})")
    features = np.ascontiguousarray(X, dtype=np.float32)
    total = np.zeros((X.shape[0], forest.n_outputs_))
    for tree in forest.estimators_:
        total += tree.predict(features, check_input=False)
    total /= len(forest.estimators_)
    return total


def _check_tree(tree: Any, index: int, n_features: int, n_outputs: int) -> None:
    """One loaded tree: the right types and sizes, children later in the tree, split features in range, finite values."""
    if type(tree) is not DecisionTreeRegressor or tree.n_features_in_ != n_features or tree.n_outputs_ != n_outputs:
        raise ValueError(f"tree {index} is not a fitted DecisionTreeRegressor of {n_features} features and {n_outputs} outputs")
    structure = tree.tree_
    if type(structure) is not Tree:
        raise ValueError(f"tree {index}'s tree_ is a {type(structure).__name__}, not scikit-learn's Tree")
    if structure.n_features != n_features or structure.n_outputs != n_outputs or structure.max_n_classes != 1:
        raise ValueError(f"tree {index} has {structure.n_features} features and {structure.n_outputs} outputs")
    nodes = structure.node_count
    left, right, feature = structure.children_left, structure.children_right, structure.feature
    leaf = left == _TREE_LEAF
    if nodes < 1 or np.any(leaf != (right == _TREE_LEAF)):
        raise ValueError(f"tree {index} children: a node has exactly one child, or the tree has no node")
    internal, position = ~leaf, np.arange(nodes)
    for name, child in (("children_left", left), ("children_right", right)):
        bad = internal & ((child <= position) | (child >= nodes))
        if np.any(bad):
            node = int(np.argmax(bad))
            raise ValueError(f"tree {index} {name}[{node}] = {child[node]} is out of range (expected a later node of the tree or -1)")
    bad_feature = internal & ((feature < 0) | (feature >= n_features))
    if np.any(bad_feature):
        node = int(np.argmax(bad_feature))
        raise ValueError(f"tree {index} feature[{node}] = {feature[node]}; expected 0..{n_features - 1}")
    if not np.all(np.isfinite(structure.threshold[internal])) or not np.all(np.isfinite(structure.value)):
        raise ValueError(f"tree {index} holds non-finite thresholds or values")


def check_forest(
    forest: Any, *, trees: int, max_depth: int | None, seed: int, n_features: int, name: str = "forest"
) -> RandomForestRegressor:
    """A forest read from a file, checked to be the one these parameters fit, with sound trees.

    Raises:
        ValueError: (naming the forest ``name``) another type or other hyper-parameters, another
            number of trees, features or outputs, or a tree whose children, split features or
            values are out of range.
    """
    try:
        return _check_forest(forest, trees, max_depth, seed, n_features)
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None


def _check_forest(forest: Any, trees: int, max_depth: int | None, seed: int, n_features: int) -> RandomForestRegressor:
    if type(forest) is not RandomForestRegressor:
        raise ValueError(f"holds a {type(forest).__name__}; expected a RandomForestRegressor")
    expected = _unfitted(trees, max_depth, seed).get_params(deep=False)
    found = forest.get_params(deep=False)
    if found != expected:
        differences = sorted(key for key in set(found) | set(expected) if found.get(key) != expected.get(key))
        raise ValueError(f"the forest's hyper-parameters {differences} are not those of its parameters")
    estimators = getattr(forest, "estimators_", None)
    if not isinstance(estimators, list) or len(estimators) != trees:
        raise ValueError(f"the forest holds {len(estimators) if isinstance(estimators, list) else 'no'} trees; its parameters say {trees}")
    counts = (getattr(forest, "n_features_in_", None), getattr(forest, "n_outputs_", None))
    if not all(isinstance(count, int | np.integer) and not isinstance(count, bool) for count in counts):  # 3.0 == 3
        raise ValueError(f"the forest's feature and output counts are {counts!r}; expected ints")
    if forest.n_features_in_ != n_features or forest.n_outputs_ != _OUTPUTS:
        raise ValueError(f"the forest has {forest.n_features_in_} features, {forest.n_outputs_} outputs; expected {n_features}, {_OUTPUTS}")
    for index, tree in enumerate(estimators):
        _check_tree(tree, index, n_features, _OUTPUTS)
    return forest


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
    TRUSTED_TYPES = FOREST_TYPES

    def __init__(self, *, trees: int = 100, max_depth: int | None = None, seed: int = 0) -> None:
        _check_forest_params(trees, max_depth, seed)
        self.trees = int(trees)
        self.max_depth = None if max_depth is None else int(max_depth)
        self.seed = int(seed)
        self.forest_: RandomForestRegressor | None = None

    def fit(self, X: np.ndarray, y: np.ndarray) -> ForestCalibrator:
        """Fit on inputs X (N, 6: metres, radians) and base positions y (N, 3, metres)."""
        X = check_inputs(X)
        y = check_targets(y, X.shape[0])
        self.forest_ = fit_forest(encode_euler(X), y, trees=self.trees, max_depth=self.max_depth, seed=self.seed)
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Base positions (N, 3) in metres for inputs X (N, 6: metres, radians)."""
        if self.forest_ is None:
            raise ValueError("ForestCalibrator.predict called before fit")
        return forest_predict(self.forest_, encode_euler(check_inputs(X)))

    def layout(self) -> dict[str, Any]:
        """Inputs (m, rad), the forest's features, outputs (m)."""
        return calibrator_layout(EULER_FEATURES)

    def _params(self) -> dict[str, Any]:
        return {"trees": self.trees, "max_depth": self.max_depth, "seed": self.seed}

    def _export(self) -> ModelParts:
        if self.forest_ is None:
            raise ValueError("ForestCalibrator.save called before fit")
        return ModelParts(self._params(), estimators={"forest": self.forest_})

    @classmethod
    def _from_params(cls, params: Mapping[str, Any]) -> ForestCalibrator:
        require_names(params, {"trees", "max_depth", "seed"}, "parameters")
        return cls(trees=params["trees"], max_depth=params["max_depth"], seed=params["seed"])

    def _load_parts(self, parts: ModelParts) -> None:
        require_names(parts.arrays, set())
        require_names(parts.estimators, {"forest"}, "estimators")
        self.forest_ = check_forest(
            parts.estimators["forest"], trees=self.trees, max_depth=self.max_depth, seed=self.seed, n_features=len(EULER_FEATURES)
        )


def _group_name(group: int) -> str:
    """The name of a yaw group's forest in a model file: ``yaw-90``, ``yaw-45``, ``yaw+0``..."""
    return f"yaw{round(np.degrees(PAPER_YAWS_RAD[group])):+d}"


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
    TRUSTED_TYPES = FOREST_TYPES

    def __init__(self, *, trees: int = paper.RESIDUAL_FOREST_TREES, max_depth: int | None = None, seed: int = 0) -> None:
        _check_forest_params(trees, max_depth, seed)
        self.trees = int(trees)
        self.max_depth = None if max_depth is None else int(max_depth)
        self.seed = int(seed)
        self.forests_: list[RandomForestRegressor | None] | None = None

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
            fit_forest(predicted_base[groups == g], residual[groups == g], trees=self.trees, max_depth=self.max_depth, seed=self.seed)
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
                residual[rows] = forest_predict(forest, predicted_base[rows])
        return residual

    @staticmethod
    def _check(predicted_base: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        predicted_base = check_inputs(predicted_base, name="predicted_base", columns=3)
        yaw = check_inputs(np.reshape(np.asarray(yaw), (-1, 1)), "yaw", 1)[:, 0]  # its kind checked, not coerced
        if yaw.shape[0] != predicted_base.shape[0]:
            raise ValueError(f"yaw has {yaw.shape[0]} values but predicted_base has {predicted_base.shape[0]} rows")
        return predicted_base, nearest_yaw_index(yaw)

    def layout(self) -> dict[str, Any]:
        """Inputs (m, rad), each forest's features (m), outputs (m), and the yaw groups (deg)."""
        return {
            "inputs": [*_POSITION_FEATURES, "yaw_rad"],
            "features": list(_POSITION_FEATURES),
            "groups_deg": [round(float(np.degrees(yaw))) for yaw in PAPER_YAWS_RAD],
            "outputs": ["residual_bx_m", "residual_by_m", "residual_bz_m"],
        }

    def _export(self) -> ModelParts:
        if self.forests_ is None:
            raise ValueError("ResidualForests.save called before fit")
        fitted = {g: forest for g, forest in enumerate(self.forests_) if forest is not None}
        params = {"trees": self.trees, "max_depth": self.max_depth, "seed": self.seed, "groups": list(fitted)}
        return ModelParts(params, estimators={_group_name(g): forest for g, forest in fitted.items()})

    @classmethod
    def _from_params(cls, params: Mapping[str, Any]) -> ResidualForests:
        require_names(params, {"trees", "max_depth", "seed", "groups"}, "parameters")
        model = cls(trees=params["trees"], max_depth=params["max_depth"], seed=params["seed"])
        groups = params["groups"]
        if (
            not isinstance(groups, list)
            or not all(isinstance(g, int) and not isinstance(g, bool) for g in groups)  # 1.0 == 1 would pass the set test
            or not set(groups) <= set(range(len(PAPER_YAWS_RAD)))
            or len(set(groups)) != len(groups)
        ):
            raise ValueError(f"groups {groups!r}; expected a list of distinct indices 0..4")
        return model

    def _load_parts(self, parts: ModelParts) -> None:
        groups = parts.params["groups"]
        require_names(parts.arrays, set())
        require_names(parts.estimators, {_group_name(g) for g in groups}, "estimators")
        self.forests_ = [
            check_forest(
                parts.estimators[_group_name(g)],
                trees=self.trees,
                max_depth=self.max_depth,
                seed=self.seed,
                n_features=len(_POSITION_FEATURES),
                name=_group_name(g),
            )
            if g in groups
            else None
            for g in range(len(PAPER_YAWS_RAD))
        ]
