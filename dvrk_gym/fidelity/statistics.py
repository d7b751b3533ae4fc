"""Statistics of a Phase I data set that tell a simulated robot from the real one.

One function, :func:`fidelity_statistics`, computes them from kept Phase I rows, real or
simulated, with the same code: the rows ``X`` are (cx, cy, cz, yaw, pitch, roll), the
marker's position in the left camera's frame in metres (z along the camera's view axis)
and the robot's reported orientation in radians; ``y`` is (bx, by, bz), the reported base
position in metres; rows are in collection order.

Definitions (the issue 15 table; on the authors' 1939 rows they give 6.6 mm, 0.89, 5.2 mm,
1.0 mm, .13/.30/.28/.20/.09, -11 to 21 deg and 3.76 / 5.0 mm^2; beyond the table, a same
reported position for 0.03 of consecutive pairs, a pitch autocorrelation of 0.27 and rows
whose plane is tilted 7.2 degrees in the robot's frame):

- Rigid residual: for each nearest paper yaw (-90, -45, 0, 45, 90 deg) a least-squares
  rigid transform ``b ~= R c + t`` (:class:`RigidBodyCalibrator`, the paper's RBT); the
  residual is the camera position it leaves unexplained, in the camera frame:
  ``c - R^T (b - t)``. Its RMS norm (equal in both frames) and the share of its energy
  along camera z, ``sum(r_z^2) / sum(|r|^2)``.
- Sample-to-sample jitter: the per-axis standard deviation of a noise independent from row
  to row, estimated as ``RMS(r[i+1] - r[i]) / sqrt(2)`` over consecutive rows whose reported
  base positions lie within ``JITTER_MAX_STEP_M`` of each other (the same pause or the next
  one: across a larger jump, between trajectories or past many dropped rows, the smooth
  cable bias changes too). Along the view axis the RMS is of ``r_z``; in the image plane it
  is of ``r_x`` and ``r_y`` pooled, so both are per-axis figures.
- Same reported position: the share of consecutive rows whose reported base positions lie
  within ``SAME_POSITION_M`` of each other. The authors' protocol commands four orientations
  at every pause of the arm's path, so a robot that reports its command repeats the
  position up to three times a pause; the real rows do so for 3% of their pairs.
- Pitch autocorrelation: the correlation of consecutive rows' pitch (lag 1). The protocol
  draws each random orientation afresh; the real rows' consecutive pitches are correlated.
- Tilt of the rows' plane: the angle between the base frame's xy-plane and the
  least-squares plane ``bz = a bx + b by + c`` through the rows' reported positions,
  ``atan(hypot(a, b))`` in degrees; ``(a, b)`` are kept too. The authors' collector ran
  each trajectory between heights over a plane it fitted through four corners where the
  arm touched the paper, so the rows' plane is the paper as the robot reported it.
- Kept rows per nearest yaw: the fraction of rows whose yaw is nearest each paper yaw.
- Pitch of kept rows: the 5th and 95th percentiles, degrees in the report.
- Cross-validation as the authors ran it: ``CV_FOLDS`` contiguous, unshuffled folds
  (sklearn ``KFold(shuffle=False)``), mean over folds of the mean squared L2 error of the
  held-out base positions (mm^2); scikit-learn's ``LinearRegression`` and a
  ``RandomForestRegressor`` (``CV_FOREST_TREES`` trees, default depth) on the six raw input
  columns, as in the authors' code (their forest had 1000 trees: 5.03 mm^2; 100 trees give
  5.00 in a tenth of the time).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from sklearn.ensemble import RandomForestRegressor
from sklearn.linear_model import LinearRegression

from dvrk_gym.calibration.models.features import PAPER_YAWS_RAD, check_inputs, check_targets, nearest_yaw_index
from dvrk_gym.calibration.models.rigid import MIN_GROUP_ROWS, RigidBodyCalibrator
from dvrk_gym.calibration.models.two_phase import Regressor
from dvrk_gym.calibration.search import cross_validate
from dvrk_gym.utils.checks import check_int

__all__ = [
    "CV_FOLDS",
    "CV_FOREST_TREES",
    "JITTER_MAX_STEP_M",
    "PLANE_MIN_WIDTH",
    "SAME_POSITION_M",
    "PAPER_YAWS_DEG",
    "FidelityStatistics",
    "consecutive_pairs",
    "lag_one_correlation",
    "plane_slope",
    "tilt_deg",
    "contiguous_cv_mse_mm2",
    "fidelity_statistics",
    "finite_or_none",
    "named_statistics",
    "rigid_residuals_camera",
]

JITTER_MAX_STEP_M = 0.010
"""Consecutive rows count for the jitter when their reported base positions are this close, m."""
PLANE_MIN_WIDTH = 0.05
"""The narrowest cloud of points :func:`plane_slope` fits a plane to: seen from above, its
spread across its main line over its spread along it (the singular values of the centred
x, y). The real Phase I rows give 0.83 (their workspace is nearly square); a collection
under 0.05 never left one line, and its plane's tilt across that line is noise."""
SAME_POSITION_M = 0.0002
"""Consecutive rows whose reported base positions lie this close count as one position, m
(the real rows' steps between pauses are 2 mm: :data:`dvrk_gym.paper.PHASE1_STEP_M`)."""
CV_FOLDS = 10
"""Folds of the authors' cross-validation (contiguous, unshuffled)."""
CV_FOREST_TREES = 100
"""Trees of the cross-validated random forest (scikit-learn's default)."""
PAPER_YAWS_DEG = tuple(float(yaw) for yaw in np.rad2deg(PAPER_YAWS_RAD))
"""The paper's five yaws, degrees, in the order of ``kept_fraction_per_yaw``."""
PITCH_PERCENTILES = (5.0, 95.0)
_M_TO_MM = 1e3
_M2_TO_MM2 = 1e6
# A camera-frame marker lies within a metre of the lens, and an angle within 2 pi; a larger
# value means millimetres or degrees were passed.
_MAX_POSITION_M = 1.0
_MAX_ANGLE_RAD = 2.0 * np.pi


@dataclass(frozen=True)
class FidelityStatistics:
    """The statistics of one Phase I data set (module docstring: definitions).

    Attributes:
        rows: kept rows used.
        rigid_residual_rms_mm: RMS norm of the per-yaw rigid fit's residual, mm.
        view_axis_share: share of that residual's energy along camera z, in [0, 1].
        view_axis_jitter_mm: sample-to-sample jitter along camera z, mm.
        image_plane_jitter_mm: sample-to-sample jitter per image-plane axis (camera x, y), mm.
        jitter_pairs: consecutive row pairs the jitter was measured on.
        same_position_share: share of consecutive row pairs whose reported base positions
            lie within ``SAME_POSITION_M`` of each other, in [0, 1].
        pitch_autocorrelation: correlation of consecutive rows' pitch (lag 1), in [-1, 1]
            (0 when the pitch does not vary).
        plane_tilt_deg: tilt of the least-squares plane through the reported positions
            from the base xy-plane, degrees, in [0, 90); nan when they define no plane
            (:func:`plane_slope`: a short collection can stay near one line).
        plane_slope: ``(a, b)`` of that plane, ``bz = a bx + b by + c``: metres of height
            per metre along base x and y (nan, nan without a plane).
        kept_fraction_per_yaw: fraction of rows nearest each of ``PAPER_YAWS_DEG``.
        pitch_p5_deg: 5th percentile of the rows' pitch, degrees.
        pitch_p95_deg: 95th percentile of the rows' pitch, degrees.
        pitch_median_per_yaw_deg: median pitch of the rows nearest each of
            ``PAPER_YAWS_DEG``, degrees (nan for a yaw without rows). The touches of
            GridTouch use one pitch per yaw (0 at yaw -90 to 10 at yaw 90), so a yaw whose
            kept rows lie far from it leaves the DNN extrapolating there.
        cv_linear_mm2: contiguous 10-fold CV of linear regression, mm^2 (None if not run).
        cv_forest_mm2: the same for the random forest, mm^2 (None if not run).
    """

    rows: int
    rigid_residual_rms_mm: float
    view_axis_share: float
    view_axis_jitter_mm: float
    image_plane_jitter_mm: float
    jitter_pairs: int
    same_position_share: float
    pitch_autocorrelation: float
    plane_tilt_deg: float
    plane_slope: tuple[float, float]
    kept_fraction_per_yaw: tuple[float, ...]
    pitch_p5_deg: float
    pitch_p95_deg: float
    pitch_median_per_yaw_deg: tuple[float, ...]
    cv_linear_mm2: float | None
    cv_forest_mm2: float | None

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready dict (tuples as lists)."""
        values = asdict(self)
        values["kept_fraction_per_yaw"] = list(self.kept_fraction_per_yaw)
        # No plane, or a yaw without rows and so no median: None (JSON null), not NaN (not JSON).
        values["plane_tilt_deg"] = finite_or_none(self.plane_tilt_deg)
        values["plane_slope"] = [finite_or_none(s) for s in self.plane_slope]
        values["pitch_median_per_yaw_deg"] = [finite_or_none(p) for p in self.pitch_median_per_yaw_deg]
        return values


def finite_or_none(value: float) -> float | None:
    """``value``, or None (JSON null) where it is undefined (nan): a yaw without rows has no
    median pitch, and rows near one line no plane to tilt."""
    return value if math.isfinite(value) else None


def _check_units(X: np.ndarray, y: np.ndarray) -> None:
    largest = max(np.abs(X[:, :3]).max(), np.abs(y).max())
    if largest > _MAX_POSITION_M:
        raise ValueError(f"positions reach {largest:.3g}; expected metres (within {_MAX_POSITION_M} m)")
    if np.abs(X[:, 3:]).max() > _MAX_ANGLE_RAD:
        raise ValueError(f"angles reach {np.abs(X[:, 3:]).max():.3g}; expected radians (within 2 pi)")


def rigid_residuals_camera(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The per-yaw rigid fit's residual in the camera frame, ``c - R^T (b - t)``.

    Args:
        X: (N, 6) camera position (m) and yaw, pitch, roll (rad).
        y: (N, 3) reported base position (m).

    Returns:
        (N, 3) residual along camera x, y (image plane) and z (view axis), metres.
    """
    X = check_inputs(X)
    y = check_targets(y, X.shape[0])
    model = RigidBodyCalibrator().fit(X, y)
    assert model.rotations_ is not None and model.translations_ is not None
    groups = nearest_yaw_index(X[:, 3])
    base_residual = y - model.predict(X)
    # b - (R c + t) = -R (c - R^T (b - t)): rotate back and flip the sign.
    return -np.einsum("nji,nj->ni", model.rotations_[groups], base_residual)


def plane_slope(positions: np.ndarray) -> tuple[float, float]:
    """The slopes ``(a, b)`` of the least-squares plane ``z = a x + b y + c`` through
    ``positions`` (N, 3), N >= 3, in metres: metres of height per metre along x and y.

    Raises:
        ValueError: on a shape other than (N, 3) with N >= 3, values not finite, or points
            that do not span the xy-plane: seen from above, their spread across their main
            line is under :data:`PLANE_MIN_WIDTH` of their spread along it (a plane through
            nearly collinear points turns on noise, and its tilt means nothing).
    """
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 2 or positions.shape[1] != 3 or positions.shape[0] < 3 or not np.isfinite(positions).all():
        raise ValueError(f"positions must be (N, 3) finite metres with N >= 3, got shape {positions.shape}")
    spread = np.linalg.svd(positions[:, :2] - positions[:, :2].mean(axis=0), compute_uv=False)  # along, across the main line
    if spread[1] == 0.0 or spread[1] < PLANE_MIN_WIDTH * spread[0]:
        width = spread[1] / spread[0] if spread[0] > 0.0 else 0.0
        raise ValueError(
            f"the positions lie on one line seen from above (their width across it is {width:.2g} of their length, "
            f"under {PLANE_MIN_WIDTH}); they define no plane"
        )
    design = np.column_stack([positions[:, 0], positions[:, 1], np.ones(positions.shape[0])])
    coefficients = np.linalg.lstsq(design, positions[:, 2], rcond=None)[0]
    return float(coefficients[0]), float(coefficients[1])


def tilt_deg(slope: tuple[float, float]) -> float:
    """The angle (degrees) between the xy-plane and a plane of slopes ``(a, b)`` (:func:`plane_slope`)."""
    return float(np.rad2deg(np.arctan(math.hypot(*slope))))


def consecutive_pairs(y: np.ndarray, max_step_m: float = JITTER_MAX_STEP_M) -> np.ndarray:
    """Indices ``i`` such that rows ``i`` and ``i + 1`` are within ``max_step_m`` in base position."""
    return np.flatnonzero(_steps(y) <= max_step_m)


def _steps(y: np.ndarray) -> np.ndarray:
    """(N - 1,) distance between consecutive reported base positions, m."""
    return np.linalg.norm(np.diff(np.asarray(y, dtype=float), axis=0), axis=1)


def lag_one_correlation(values: np.ndarray) -> float:
    """Pearson correlation of consecutive values (lag 1); 0 when either side does not vary.

    Args:
        values: (N,) a sequence, N >= 2 (any unit: the correlation has none).
    """
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or values.size < 2:
        raise ValueError(f"values must be a sequence of at least 2 numbers, got shape {values.shape}")
    earlier, later = values[:-1], values[1:]
    if np.ptp(earlier) == 0.0 or np.ptp(later) == 0.0:  # np.corrcoef would divide by zero
        return 0.0
    return float(np.corrcoef(earlier, later)[0, 1])


def contiguous_cv_mse_mm2(make: Callable[[], Regressor], X: np.ndarray, y: np.ndarray, folds: int = CV_FOLDS) -> float:
    """Mean over contiguous, unshuffled folds of the held-out mean squared L2 error, mm^2
    (the model search's :func:`~dvrk_gym.calibration.search.cross_validate`, unshuffled)."""
    return float(np.mean(cross_validate(lambda _seed: make(), X, y, folds=folds, shuffle=False)))


def fidelity_statistics(
    X: np.ndarray, y: np.ndarray, *, cross_validation: bool = True, folds: int = CV_FOLDS, seed: int = 0
) -> FidelityStatistics:
    """Every statistic of the fidelity table for one set of kept Phase I rows.

    Args:
        X: (N, 6) camera-frame marker position (m), then reported yaw, pitch, roll (rad),
            in collection order.
        y: (N, 3) reported base position (m).
        cross_validation: run the two cross-validations (about 5 s on 1939 rows); when
            False their fields are None.
        folds: folds of the cross-validation (the authors: 10).
        seed: seeds the random forest.

    Raises:
        ValueError: on bad shapes, non-finite values, units that are not metres and
            radians, fewer rows than a rigid fit needs (3) or, with ``cross_validation``,
            than ``folds``, or no consecutive pair for the jitter.
    """
    folds = check_int("folds", folds, 2, 1000)
    X = check_inputs(X)
    y = check_targets(y, X.shape[0])
    _check_units(X, y)
    needed = max(folds, MIN_GROUP_ROWS) if cross_validation else MIN_GROUP_ROWS
    if X.shape[0] < needed:
        why = f"a rigid fit needs {MIN_GROUP_ROWS}" + (f", the cross-validation's {folds} folds {folds}" if cross_validation else "")
        raise ValueError(f"X has {X.shape[0]} rows; the statistics need at least {needed} ({why})")
    residual = rigid_residuals_camera(X, y)
    energy = np.sum(residual**2, axis=0)
    steps = _steps(y)
    pairs = np.flatnonzero(steps <= JITTER_MAX_STEP_M)  # consecutive_pairs(y), from the steps it needs anyway
    if pairs.size == 0:
        raise ValueError(f"no consecutive rows lie within {JITTER_MAX_STEP_M} m of each other; the jitter needs at least one pair")
    jumps = residual[pairs + 1] - residual[pairs]
    groups = nearest_yaw_index(X[:, 3])
    pitch_deg = np.rad2deg(X[:, 4])
    try:
        slope = plane_slope(y)
    except ValueError:  # the rows lie near one line seen from above: no tilt, and the comparison fails its row
        slope = (math.nan, math.nan)
    linear = forest = None
    if cross_validation:
        linear = contiguous_cv_mse_mm2(LinearRegression, X, y, folds)
        forest = contiguous_cv_mse_mm2(
            lambda: RandomForestRegressor(n_estimators=CV_FOREST_TREES, random_state=seed, n_jobs=1), X, y, folds
        )
    return FidelityStatistics(
        rows=int(X.shape[0]),
        rigid_residual_rms_mm=float(np.sqrt(energy.sum() / X.shape[0]) * _M_TO_MM),
        view_axis_share=float(energy[2] / energy.sum()) if energy.sum() > 0 else 0.0,
        view_axis_jitter_mm=float(np.sqrt(np.mean(jumps[:, 2] ** 2) / 2.0) * _M_TO_MM),
        image_plane_jitter_mm=float(np.sqrt(np.mean(jumps[:, :2] ** 2) / 2.0) * _M_TO_MM),
        jitter_pairs=int(pairs.size),
        same_position_share=float(np.mean(steps <= SAME_POSITION_M)),
        pitch_autocorrelation=lag_one_correlation(X[:, 4]),
        plane_tilt_deg=tilt_deg(slope),
        plane_slope=slope,
        kept_fraction_per_yaw=tuple(float(f) for f in np.bincount(groups, minlength=len(PAPER_YAWS_RAD)) / X.shape[0]),
        pitch_p5_deg=float(np.percentile(pitch_deg, PITCH_PERCENTILES[0])),
        pitch_p95_deg=float(np.percentile(pitch_deg, PITCH_PERCENTILES[1])),
        pitch_median_per_yaw_deg=tuple(
            float(np.median(pitch_deg[groups == g])) if np.any(groups == g) else float("nan") for g in range(len(PAPER_YAWS_RAD))
        ),
        cv_linear_mm2=linear,
        cv_forest_mm2=forest,
    )


def named_statistics(stats: FidelityStatistics, kept_share: float | None = None) -> list[tuple[str, float, str]]:
    """Each statistic of the fidelity table as ``(name with its unit, value, kind)``, in the issue's order.

    ``kind`` says how a comparison judges it: "ratio", "share", "correlation" or "median
    pitch". ``kept_share`` is the kept share of raw rows (not a statistic of the kept rows;
    None leaves it out); the cross-validations are there when they were run.
    """
    named = [
        ("rigid residual RMS (mm)", stats.rigid_residual_rms_mm, "ratio"),
        ("residual share along view axis", stats.view_axis_share, "share"),
        ("jitter along view axis (mm)", stats.view_axis_jitter_mm, "ratio"),
        ("jitter in image plane (mm)", stats.image_plane_jitter_mm, "ratio"),
        ("same reported position, consecutive rows (share)", stats.same_position_share, "share"),
        ("pitch autocorrelation, consecutive rows", stats.pitch_autocorrelation, "correlation"),
        ("tilt of the rows' plane in the base frame (deg)", stats.plane_tilt_deg, "ratio"),
    ]
    named += [(f"kept rows at yaw {yaw:+.0f} (share)", f, "share") for yaw, f in zip(PAPER_YAWS_DEG, stats.kept_fraction_per_yaw)]
    if kept_share is not None:
        named.append(("kept share of raw rows", kept_share, "share"))
    named += [
        ("pitch of kept rows, 5th pct (deg)", stats.pitch_p5_deg, "ratio"),
        ("pitch of kept rows, 95th pct (deg)", stats.pitch_p95_deg, "ratio"),
    ]
    named += [
        (f"median pitch at yaw {yaw:+.0f} (deg)", pitch, "median pitch")
        for yaw, pitch in zip(PAPER_YAWS_DEG, stats.pitch_median_per_yaw_deg)
    ]
    if stats.cv_linear_mm2 is not None:
        named.append(("contiguous 10-fold CV, linear (mm^2)", stats.cv_linear_mm2, "ratio"))
    if stats.cv_forest_mm2 is not None:
        named.append(("contiguous 10-fold CV, forest (mm^2)", stats.cv_forest_mm2, "ratio"))
    return named
