"""The red-tape detector's error, identified from the rows' left/right row differences.

The authors triangulated with the disparity ``|left - right|`` of whole-pixel detections
(``camera_pixels_to_camera_coords`` in their code), so each row's depth gives back that
length exactly, and with it the whole-pixel horizontal disparity and row difference
(:func:`row_differences`; where a length has several such splits, the smallest row
difference is taken). A rectified pair sees a point on one row, so the row difference is
the difference of the two cameras' detection errors, truncated to whole pixels. Each
camera's error is modelled as :class:`~dvrk_gym.sim.endoscope.noise.DetectionNoise` (a
Gaussian core and rare outliers); :func:`fit_detector_noise` fits it by maximum
likelihood to the histogram of row differences up to ``MAX_ROW_DIFFERENCE_PX`` (larger
ones are rare, and the authors' 12 px gate cuts them).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.stats import chisquare, norm

from dvrk_gym import paper
from dvrk_gym.fidelity.instrument_model import pixels_of_camera_points
from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.sim.endoscope.noise import DetectionNoise, whole_pixels
from dvrk_gym.utils.checks import check_int

__all__ = [
    "MAX_ROW_DIFFERENCE_PX",
    "row_differences",
    "row_difference_probabilities",
    "fit_detector_noise",
    "histogram",
    "held_out_pvalue",
    "disparity_noise_px",
    "plane_noise_mm",
]

MAX_ROW_DIFFERENCE_PX = 10
"""Row differences fitted: 0 to this many pixels."""
_SEARCH_ROWS_PX = 40
_EXACT_PX = 1e-6
_GRID_PX = np.linspace(-40.0, 40.0, 16001)


def row_differences(X: np.ndarray) -> np.ndarray:
    """The whole-pixel row difference |v_left - v_right| behind each row, (N,) int px.

    Raises:
        ValueError: a row's disparity is not the length of a vector of whole pixels (the
            rows did not come from the authors' cameras and triangulation).
    """
    disparity = paper.ENDOSCOPE_FOCAL_PX * paper.ENDOSCOPE_BASELINE_M / X[:, 2]
    found = np.full(len(X), -1)
    for k in range(_SEARCH_ROWS_PX, -1, -1):  # the last hit is the smallest row difference
        horizontal = np.sqrt(np.maximum(disparity**2 - k * k, 0.0))  # 0, a whole number, where k exceeds the disparity
        found[(k <= disparity) & (np.abs(horizontal - np.round(horizontal)) < _EXACT_PX)] = k
    if (found < 0).any():
        bad = np.flatnonzero(found < 0)
        raise ValueError(f"rows {bad[:10].tolist()} have a disparity that is no length of whole pixels; not the authors' triangulation")
    return found


def histogram(differences: np.ndarray) -> np.ndarray:
    """Counts of row differences 0 .. MAX_ROW_DIFFERENCE_PX, (MAX_ROW_DIFFERENCE_PX + 1,)."""
    return np.bincount(np.minimum(differences, MAX_ROW_DIFFERENCE_PX + 1), minlength=MAX_ROW_DIFFERENCE_PX + 2)[:-1]


def row_difference_probabilities(noise: DetectionNoise) -> np.ndarray:
    """P(|row difference| = k) for k = 0 .. MAX_ROW_DIFFERENCE_PX, normalised over that range.

    The difference e of two cameras' errors is a mixture of three zero-mean normals (core
    and core, core and outlier, outlier and outlier); truncating two coordinates that share
    their fractional part to whole pixels gives floor(e) or ceil(e), the latter with
    probability frac(e): a triangular kernel of half-width 1 px over e.
    """
    c2, o2, p = noise.core_px**2, noise.outlier_px**2, noise.outlier_probability
    density = sum(w * norm.pdf(_GRID_PX, 0.0, np.sqrt(v)) for v, w in ((2 * c2, (1 - p) ** 2), (c2 + o2, 2 * p * (1 - p)), (2 * o2, p * p)))
    step = _GRID_PX[1] - _GRID_PX[0]
    signed = np.array([np.sum(np.clip(1.0 - np.abs(_GRID_PX - m), 0.0, None) * density) * step for m in range(MAX_ROW_DIFFERENCE_PX + 1)])
    folded = signed * np.where(np.arange(MAX_ROW_DIFFERENCE_PX + 1) == 0, 1.0, 2.0)
    return folded / folded.sum()


def _noise(t: np.ndarray) -> DetectionNoise:
    return DetectionNoise(float(np.exp(t[0])), float(np.exp(t[1])), float(1.0 / (1.0 + np.exp(-t[2]))))


def _check_counts(counts: np.ndarray) -> np.ndarray:
    counts = np.asarray(counts)
    bins = MAX_ROW_DIFFERENCE_PX + 1
    if (
        counts.shape != (bins,)
        or counts.dtype.kind not in "fiu"
        or not np.isfinite(counts).all()
        or (counts < 0).any()
        or counts.sum() <= 0
    ):
        raise ValueError(
            f"counts must be a histogram of {bins} finite, non-negative counts (row differences 0 .. "
            f"{MAX_ROW_DIFFERENCE_PX} px) holding some rows, got {np.array2string(counts, threshold=12)} of shape {counts.shape}"
        )
    return counts


def fit_detector_noise(counts: np.ndarray) -> DetectionNoise:
    """Maximum-likelihood detector noise for a histogram of row differences (:func:`histogram`).

    Raises:
        ValueError: ``counts`` is not a histogram of :func:`histogram`'s shape (one count per
            row difference 0 .. ``MAX_ROW_DIFFERENCE_PX``) of finite, non-negative counts with
            at least one row (an empty histogram would "fit" at the optimiser's starting point).
    """
    counts = _check_counts(counts)

    def negative_log_likelihood(t: np.ndarray) -> float:
        return float(-np.sum(counts * np.log(row_difference_probabilities(_noise(t)) + 1e-300)))

    start = np.array([np.log(1.0), np.log(4.0), -2.0])
    result = minimize(negative_log_likelihood, start, method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-6, "maxiter": 4000})
    return _noise(result.x)


def held_out_pvalue(noise: DetectionNoise, counts: np.ndarray, max_px: int = 8) -> float:
    """Chi-square p-value of held-out counts (0 .. max_px px, pooled beyond) against the fitted noise.

    Raises:
        ValueError: ``counts`` is not a histogram of :func:`histogram`'s shape, or ``max_px``
            not an int in [1, ``MAX_ROW_DIFFERENCE_PX``].
    """
    counts = _check_counts(counts)
    max_px = check_int("max_px", max_px, 1, MAX_ROW_DIFFERENCE_PX)
    probabilities = row_difference_probabilities(noise)
    observed = np.append(counts[:max_px], counts[max_px:].sum())
    expected = np.append(probabilities[:max_px], probabilities[max_px:].sum()) * observed.sum()
    return float(chisquare(observed, expected).pvalue)


def disparity_noise_px(noise: DetectionNoise) -> float:
    """RMS error of a disparity from two such detections truncated to whole pixels, px."""
    per_camera = (1 - noise.outlier_probability) * noise.core_px**2 + noise.outlier_probability * noise.outlier_px**2
    return float(np.sqrt(2.0 * per_camera + 1.0 / 6.0))


def plane_noise_mm(noise: DetectionNoise, camera_points_m: np.ndarray, *, draws: int = 16, seed: int = 0) -> float:
    """RMS error per image-plane axis (camera x, y) that this detector gives stereo positions at these points, mm.

    Each point (left camera frame, m) is projected into both cameras of the authors'
    rectified pair, each camera's detection errs by its own draw and is truncated to whole
    pixels, and the pair is triangulated as the authors did
    (:meth:`~dvrk_gym.sim.endoscope.camera.StereoCamera.triangulate`: the disparity is the
    length ``|left - right|``; x and y are the left pixel's ray at that depth). A camera x is
    ``(u - cx) z / f``: the depth's noise, the disparity's, reaches the image plane too,
    by x / z of it, which for a tape 10 to 30 mm off the optical axis outweighs the left
    pixel's own error. The figure is each point's scatter about its own mean over
    ``draws`` draws, pooled over the points and both axes. A point's truncation error
    counts only as far as the noise spreads it over the pixel grid: at the identified
    noise (a core of 0.82 px) that is all of it, but with no noise a point's rounding is
    the same at every draw and counts nothing, though consecutive rows at different
    positions would see it as jitter (at most 0.03 mm per axis at these depths).

    Raises:
        ValueError: points not (N >= 1, 3) finite with z > 0, draws not in [2, 100000],
            more than 10,000,000 detections in all, or a draw whose disparity is not positive.
    """
    points = np.asarray(camera_points_m, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] == 0 or not np.all(np.isfinite(points)) or np.any(points[:, 2] <= 0):
        raise ValueError(f"camera_points_m has shape {points.shape}; expected (N >= 1, 3) finite points in front of the camera (z > 0)")
    draws = check_int("draws", draws, 2, 100_000)
    if points.shape[0] * draws > 10_000_000:
        raise ValueError(f"{points.shape[0]} points x {draws} draws is over 10,000,000 detections; pass fewer")
    rng = np.random.default_rng(seed)
    left_u, v, disparity = (np.repeat(column, draws) for column in pixels_of_camera_points(points).T)
    width = paper.ENDOSCOPE_RESOLUTION_PX[0]
    left = whole_pixels(np.stack([left_u, v], axis=1) + noise.sample_many(rng, (len(left_u),)), width)
    right = whole_pixels(np.stack([left_u - disparity, v], axis=1) + noise.sample_many(rng, (len(left_u),)), width)
    if np.any(left[:, 0] - right[:, 0] <= 0):
        raise ValueError("the detector's noise gave a non-positive disparity: the points are too far, or the noise too large")
    plane = StereoCamera().triangulate(left, right)[:, :2].reshape(len(points), draws, 2)
    scatter = plane - plane.mean(axis=1, keepdims=True)
    return float(np.sqrt(np.mean(scatter**2) * draws / (draws - 1)) * 1e3)
