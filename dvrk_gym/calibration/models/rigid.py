"""The paper's rigid-body baseline: one rotation and translation per yaw group.

For each of the five paper yaws (-90, -45, 0, 45, 90 deg), the rows whose yaw is nearest to
it give a least-squares rigid transform ``b = R c + t`` from camera position ``c`` to base
position ``b`` (Kabsch / orthogonal Procrustes, a proper rotation, det R = +1). Pitch and
roll are not used, as in the paper.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_gym.calibration.models.features import PAPER_YAWS_RAD, calibrator_layout, check_inputs, check_targets, nearest_yaw_index
from dvrk_gym.calibration.models.serialization import ModelParts, SavableModel, require_array, require_names

__all__ = ["RigidBodyCalibrator", "fit_rigid_transform"]

_LOGGER = logging.getLogger(__name__)
MIN_GROUP_ROWS = 3  # a rigid transform needs three non-collinear points
_ROTATION_TOL = 1e-9
MIN_PLANE_SPREAD_M = 1e-7
"""Rows whose second principal spread (RMS about their line of best fit) is below this, m,
lie on a line: they fix no rotation about it."""


def spans_a_plane(points: np.ndarray) -> bool:
    """Whether (N, 3) points (m) are at least three and not (near) collinear: their second
    principal RMS spread is at least ``MIN_PLANE_SPREAD_M``."""
    if len(points) < MIN_GROUP_ROWS:
        return False
    spreads = np.linalg.svd(points - points.mean(axis=0), compute_uv=False) / np.sqrt(len(points))
    return bool(spreads[1] >= MIN_PLANE_SPREAD_M)


def fit_rigid_transform(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation and translation with ``target ~= R @ source + t``.

    Args:
        source: (N, 3) points (metres), N >= 3, not all collinear.
        target: (N, 3) corresponding points (metres).

    Returns:
        ``(R, t)``: (3, 3) proper rotation and (3,) translation in metres.
    """
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    rotation, _ = Rotation.align_vectors(target - target_mean, source - source_mean)
    matrix = rotation.as_matrix()
    return matrix, target_mean - matrix @ source_mean


class RigidBodyCalibrator(SavableModel):
    """Per-yaw rigid transforms from camera position to base position.

    A yaw group whose training rows do not span a plane (fewer than three, or on a line:
    :func:`spans_a_plane`) uses the transform fitted to all rows.
    """

    KIND = "rigid_body_calibrator"

    def __init__(self) -> None:
        self.rotations_: np.ndarray | None = None  # (5, 3, 3)
        self.translations_: np.ndarray | None = None  # (5, 3), metres
        self.group_rows_: np.ndarray | None = None  # (5,) training rows per group

    def fit(self, X: np.ndarray, y: np.ndarray) -> RigidBodyCalibrator:
        """Fit on inputs X (N, 6: metres, radians) and base positions y (N, 3, metres).

        Raises:
            ValueError: On bad shapes or values, fewer than three rows in all, or rows whose
                camera positions lie on a line.
        """
        X = check_inputs(X)
        y = check_targets(y, X.shape[0])
        if X.shape[0] < MIN_GROUP_ROWS:
            raise ValueError(f"X has {X.shape[0]} rows; a rigid fit needs at least {MIN_GROUP_ROWS}")
        if not spans_a_plane(X[:, :3]):
            raise ValueError("the rows' camera positions lie on a line; a rigid fit needs three that do not")
        groups = nearest_yaw_index(X[:, 3])
        fallback = fit_rigid_transform(X[:, :3], y)
        rotations, translations = [], []
        for g in range(len(PAPER_YAWS_RAD)):
            rows = groups == g
            if spans_a_plane(X[rows, :3]):
                rotation, translation = fit_rigid_transform(X[rows, :3], y[rows])
            else:
                _LOGGER.info("yaw group %d's %d rows span no plane; using the all-data rigid transform", g, np.count_nonzero(rows))
                rotation, translation = fallback
            rotations.append(rotation)
            translations.append(translation)
        self.rotations_ = np.stack(rotations)
        self.translations_ = np.stack(translations)
        self.group_rows_ = np.bincount(groups, minlength=len(PAPER_YAWS_RAD)).astype(np.int64)
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Base positions (N, 3) in metres for inputs X (N, 6: metres, radians)."""
        if self.rotations_ is None or self.translations_ is None:
            raise ValueError("RigidBodyCalibrator.predict called before fit")
        X = check_inputs(X)
        groups = nearest_yaw_index(X[:, 3])
        rotated = np.einsum("nij,nj->ni", self.rotations_[groups], X[:, :3])
        return rotated + self.translations_[groups]

    def layout(self) -> dict[str, Any]:
        """Inputs (m, rad; only the position and the yaw are used), outputs (m)."""
        return calibrator_layout()

    def _export(self) -> ModelParts:
        if self.rotations_ is None or self.translations_ is None or self.group_rows_ is None:
            raise ValueError("RigidBodyCalibrator.save called before fit")
        return ModelParts({}, {"rotations": self.rotations_, "translations": self.translations_, "group_rows": self.group_rows_})

    @classmethod
    def _from_params(cls, params: Mapping[str, Any]) -> RigidBodyCalibrator:
        if params:
            raise ValueError(f"unexpected parameters {sorted(params)}; a rigid-body calibrator has none")
        return cls()

    def _load_parts(self, parts: ModelParts) -> None:
        groups = len(PAPER_YAWS_RAD)
        require_names(parts.estimators, set(), "estimators")
        require_names(parts.arrays, {"rotations", "translations", "group_rows"})
        rotations = require_array(parts.arrays, "rotations", (groups, 3, 3), np.float64)
        orthogonality = np.abs(rotations @ rotations.transpose(0, 2, 1) - np.eye(3)).max()
        if orthogonality > _ROTATION_TOL or np.any(np.linalg.det(rotations) < 0.0):
            raise ValueError("rotations are not proper rotation matrices")
        self.rotations_ = rotations
        self.translations_ = require_array(parts.arrays, "translations", (groups, 3), np.float64)
        self.group_rows_ = require_array(parts.arrays, "group_rows", (groups,), np.int64)
