"""Random forests as flat numpy arrays, predicted by a vectorised traversal.

scikit-learn fits the forests; we keep only each tree's node arrays (children, split
feature and threshold, leaf values), so a forest can be saved to and loaded from plain
``.npz`` without pickling sklearn objects. Prediction reproduces
``RandomForestRegressor.predict`` (to floating-point summation order: about 1e-16 relative).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from sklearn.ensemble import RandomForestRegressor

from dvrk_gym.calibration.models.serialization import require_array

__all__ = ["TreeEnsemble", "fit_forest"]

_ARRAY_NAMES = ("tree_offsets", "children_left", "children_right", "feature", "threshold", "value")
_LEAF = -1
_ROWS_PER_CHUNK = 4096  # bounds the (trees x rows) traversal state to a few MB


def fit_forest(X: np.ndarray, y: np.ndarray, trees: int, max_depth: int | None, seed: int) -> TreeEnsemble:
    """Fit a seeded ``RandomForestRegressor`` and export it.

    Args:
        X: (N, F) features.
        y: (N, K) targets.
        trees: Number of trees.
        max_depth: Maximum depth, or None for sklearn's default (grow until pure).
        seed: ``random_state`` of the forest.

    Returns:
        The forest as a :class:`TreeEnsemble`.
    """
    forest = RandomForestRegressor(n_estimators=trees, max_depth=max_depth, random_state=seed)
    forest.fit(X, y)
    return TreeEnsemble.from_sklearn(forest)


@dataclass(frozen=True, eq=False)
class TreeEnsemble:
    """All trees of a forest, concatenated.

    Attributes:
        tree_offsets: (T + 1,) int64: tree t owns nodes ``tree_offsets[t]:tree_offsets[t+1]``.
        children_left: (M,) int64: left child, as an index local to its tree, or -1 at a leaf.
        children_right: (M,) int64: right child, local index, or -1 at a leaf.
        feature: (M,) int64: split feature of internal nodes (ignored at leaves).
        threshold: (M,) float64: go left when ``x[feature] <= threshold``.
        value: (M, K) float64: node mean of the K targets (used at leaves).
    """

    tree_offsets: np.ndarray
    children_left: np.ndarray
    children_right: np.ndarray
    feature: np.ndarray
    threshold: np.ndarray
    value: np.ndarray

    @classmethod
    def from_sklearn(cls, forest: RandomForestRegressor) -> TreeEnsemble:
        """Export a fitted sklearn forest (regression, any number of outputs)."""
        trees = [estimator.tree_ for estimator in forest.estimators_]
        sizes = [tree.node_count for tree in trees]
        return cls(
            tree_offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
            children_left=np.concatenate([t.children_left for t in trees]).astype(np.int64),
            children_right=np.concatenate([t.children_right for t in trees]).astype(np.int64),
            feature=np.concatenate([t.feature for t in trees]).astype(np.int64),
            threshold=np.concatenate([t.threshold for t in trees]).astype(np.float64),
            value=np.concatenate([t.value[:, :, 0] for t in trees]).astype(np.float64),
        )

    @property
    def n_trees(self) -> int:
        """Number of trees."""
        return len(self.tree_offsets) - 1

    @property
    def n_outputs(self) -> int:
        """Number of predicted targets K."""
        return self.value.shape[1]

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Mean over trees of the leaf values reached by each row.

        Args:
            X: (N, F) features, F larger than every split feature.

        Returns:
            (N, K) float64 predictions.
        """
        # sklearn compares float32 inputs with float64 thresholds; do the same.
        X = np.asarray(X, dtype=np.float32).astype(np.float64)
        chunks = [self._predict_rows(X[start : start + _ROWS_PER_CHUNK]) for start in range(0, X.shape[0], _ROWS_PER_CHUNK)]
        return np.concatenate(chunks, axis=0) if chunks else np.zeros((0, self.n_outputs))

    def _predict_rows(self, X: np.ndarray) -> np.ndarray:
        starts = self.tree_offsets[:-1]
        node_tree = np.repeat(starts, np.diff(self.tree_offsets))
        left = np.where(self.children_left == _LEAF, _LEAF, self.children_left + node_tree)
        right = np.where(self.children_right == _LEAF, _LEAF, self.children_right + node_tree)
        feature = np.maximum(self.feature, 0)
        rows = np.arange(X.shape[0])[None, :]
        node = np.repeat(starts[:, None], X.shape[0], axis=1)  # (T, N) global node indices
        while True:  # terminates: children always have larger indices than their parent
            next_left = left[node]
            internal = next_left != _LEAF
            if not internal.any():
                break
            go_left = X[rows, feature[node]] <= self.threshold[node]
            node = np.where(internal, np.where(go_left, next_left, right[node]), node)
        return self.value[node].sum(axis=0) / self.n_trees

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """The node arrays by name, each name prefixed by ``prefix``."""
        return {prefix + name: getattr(self, name) for name in _ARRAY_NAMES}

    @staticmethod
    def array_names(prefix: str = "") -> set[str]:
        """Names written by :meth:`to_arrays` with this prefix."""
        return {prefix + name for name in _ARRAY_NAMES}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], prefix: str, n_features: int, n_outputs: int) -> TreeEnsemble:
        """Rebuild a forest from a model file's arrays, checking it is a valid forest.

        Raises:
            ValueError: On wrong shapes or dtypes, offsets that do not partition the nodes,
                children out of their tree or not after their parent (which could loop),
                half-leaves, or split features outside ``0..n_features-1``.
        """
        offsets = arrays.get(prefix + "tree_offsets")
        if offsets is None or offsets.ndim != 1 or offsets.dtype != np.int64 or offsets.size < 2:
            raise ValueError(f"{prefix}tree_offsets must be int64 of shape (trees + 1,)")
        nodes = int(offsets[-1])
        if offsets[0] != 0 or np.any(np.diff(offsets) < 1):
            raise ValueError(f"{prefix}tree_offsets must start at 0 and increase strictly")
        ensemble = cls(
            tree_offsets=offsets,
            children_left=require_array(arrays, prefix + "children_left", (nodes,), np.int64),
            children_right=require_array(arrays, prefix + "children_right", (nodes,), np.int64),
            feature=require_array(arrays, prefix + "feature", (nodes,), np.int64),
            threshold=require_array(arrays, prefix + "threshold", (nodes,), np.float64),
            value=require_array(arrays, prefix + "value", (nodes, n_outputs), np.float64),
        )
        ensemble._check_structure(prefix, n_features)
        return ensemble

    def _check_structure(self, prefix: str, n_features: int) -> None:
        sizes = np.diff(self.tree_offsets)
        local = np.arange(self.tree_offsets[-1]) - np.repeat(self.tree_offsets[:-1], sizes)
        size = np.repeat(sizes, sizes)
        left, right = self.children_left, self.children_right
        leaf = left == _LEAF
        if np.any(leaf != (right == _LEAF)):
            raise ValueError(f"{prefix}children: a node has exactly one child")
        internal = ~leaf
        for name, child in (("children_left", left), ("children_right", right)):
            bad = internal & ((child <= local) | (child >= size))
            if np.any(bad):
                node = int(np.argmax(bad))
                raise ValueError(f"{prefix}{name}[{node}] = {child[node]} is out of range (expected a later node of the same tree or -1)")
        bad_feature = internal & ((self.feature < 0) | (self.feature >= n_features))
        if np.any(bad_feature):
            node = int(np.argmax(bad_feature))
            raise ValueError(f"{prefix}feature[{node}] = {self.feature[node]}; expected 0..{n_features - 1}")
