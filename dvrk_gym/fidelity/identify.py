"""Identify the paper's instrument from the authors' real Phase I rows: fit, held-out check, uncertainty.

Three steps, each on a training part of the rows (the first ``TRAIN_FRACTION`` in
collection order) and judged on the held-out rest:

1. The deterministic parameters (:data:`~dvrk_gym.fidelity.instrument_model.PARAMETERS`:
   camera pose and depth scale, tape position, homing offsets, cable stretch, backlash) by
   maximum a posteriori least squares (``scipy.optimize.least_squares``, Huber loss, the
   parameters' Gaussian priors) on the pixel residuals of every row: left u, v and the
   disparity, each divided by its RMS after a first fit of the camera and tape alone.
   Their spread by a moving-block bootstrap of the training rows (blocks of
   ``BOOTSTRAP_BLOCK`` rows keep the residuals' serial correlation).
2. The red-tape detector's error (:class:`~dvrk_gym.sim.endoscope.noise.DetectionNoise`)
   by maximum likelihood on the rows' left/right row differences (:mod:`.detector_noise`).
3. The two noise parameters the real rows pin down only through their statistics: the
   robot's repeatability, from the sample-to-sample jitter in the image plane
   (:func:`~dvrk_gym.fidelity.statistics.fidelity_statistics`) that the fitted model and
   the detector leave on the real rows (:func:`repeatability_from_jitter`), and the
   detector's misses, from the share of rows kept against a simulated Phase I
   (:func:`match_miss_probability`).
4. The reported pose's lag (``BiasConfig.wrist_settle_lag``), from how often consecutive
   real rows report the same position, against simulated Phase I collections over a grid
   of lags (:func:`match_settle_lag`). It runs before the misses are matched again: the lag
   changes which orientations keep their tape in view.

``python benchmarks/identify_instrument.py`` runs it all and prints every figure quoted in
:mod:`dvrk_gym.sim.identified`.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import MAX_TRAJECTORIES, PaperExplorationPolicy, collect_phase1, run_paper_phase1
from dvrk_gym.envs.exploration import CalibrationExplorationEnv
from dvrk_gym.fidelity.instrument_model import PARAMETERS, initial_vector, predict_camera_points, predict_pixels
from dvrk_gym.fidelity.statistics import fidelity_statistics
from dvrk_gym.fidelity.uncertainty import block_bootstrap_rows
from dvrk_gym.sim.endoscope.camera import WORKSPACE_CENTER_M
from dvrk_gym.sim.endoscope.noise import IDENTIFIED_MARKER_NOISE, DetectionNoise
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.utils.checks import check_float, check_int

__all__ = [
    "TRAIN_FRACTION",
    "BOOTSTRAP_BLOCK",
    "CAMERA_AND_TAPE",
    "InstrumentFit",
    "split",
    "start_camera_pose",
    "fit_parameters",
    "refit",
    "prior_residuals",
    "residual_rms",
    "bootstrap_sd",
    "model_jitter_mm",
    "detector_plane_noise_mm",
    "repeatability_from_jitter",
    "MissMatch",
    "match_miss_probability",
    "SETTLE_LAG_GRID",
    "SettleLagMatch",
    "first_crossing",
    "match_settle_lag",
]

logger = logging.getLogger(__name__)

TRAIN_FRACTION = 0.7
"""The first 70% of the rows (in collection order) train; the rest is held out."""
BOOTSTRAP_BLOCK = 50
"""Rows per block of the moving-block bootstrap: the residuals' serial correlation fades
over about 20 rows (lag-10 autocorrelation of the depth residual 0.28, lag 50 0.06)."""
MAX_BOOTSTRAP_REPLICATES = 10_000
"""The most replicates :func:`bootstrap_sd` runs (each is a refit of every row)."""
HUBER_SCALE = 2.0
"""Residuals beyond this many of their scale count linearly (the detector's outliers)."""
CAMERA_AND_TAPE = tuple(range(10))
"""Indices of the camera and tape parameters: the first fit, and the baseline model."""
START_HEIGHT_M = paper.ENDOSCOPE_HEIGHT_M
"""The fit starts from a camera this far straight above the workspace centre, metres (the paper: 7.5 in)."""


START_TILT_RAD = np.deg2rad(10.0)
"""The start's camera looks down this far from the vertical: straight down is a half turn
from the base frame, where the fit's rotation vector is singular."""


def start_camera_pose() -> np.ndarray:
    """T_base_leftcam (4x4) the fit starts from: looking down on the workspace centre from START_HEIGHT_M, image x along -x."""
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec([0.0, np.pi - START_TILT_RAD, 0.0]).as_matrix()
    pose[:3, 3] = np.array(WORKSPACE_CENTER_M) - START_HEIGHT_M * pose[:3, 2]
    return pose


@dataclass(frozen=True)
class InstrumentFit:
    """A fitted parameter vector and how well it predicts the rows.

    Attributes:
        theta: the parameters (:data:`~dvrk_gym.fidelity.instrument_model.PARAMETERS` order).
        scales: (3,) the residual scales used (u, v, disparity), px.
        free: indices of the parameters fitted (the others stay at their initial values).
    """

    theta: np.ndarray
    scales: np.ndarray
    free: tuple[int, ...]


def split(n_rows: int, train_fraction: float = TRAIN_FRACTION) -> tuple[np.ndarray, np.ndarray]:
    """Training and held-out row indices: the first train_fraction of the rows, and the rest."""
    n_rows = check_int("n_rows", n_rows, 0)
    if not 0.0 < train_fraction < 1.0:
        raise ValueError(f"train_fraction = {train_fraction}; expected a value in (0, 1)")
    cut = int(round(train_fraction * n_rows))
    return np.arange(cut), np.arange(cut, n_rows)


def _residuals(free_values: np.ndarray, fit: InstrumentFit, commands: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    theta = fit.theta.copy()
    theta[list(fit.free)] = free_values
    scaled = ((predict_pixels(theta, commands) - pixels) / fit.scales).ravel()
    return np.concatenate([scaled, prior_residuals(theta, fit.free)])


def prior_residuals(theta: np.ndarray, free: tuple[int, ...]) -> np.ndarray:
    """The priors' terms of the fit's residuals: each free parameter that has a prior over its sd."""
    return np.array([theta[i] / PARAMETERS[i].prior_sd for i in free if PARAMETERS[i].prior_sd is not None], dtype=float)


def refit(fit: InstrumentFit, commands: np.ndarray, pixels: np.ndarray) -> InstrumentFit:
    """MAP fit of the parameters ``fit.free`` to rows (commands (N, 6) rad / m, pixels (N, 3)
    px), starting from ``fit.theta`` with its residual scales; the others keep their values."""
    start = fit.theta[list(fit.free)]
    result = least_squares(
        _residuals, start, args=(fit, commands, pixels), x_scale="jac", diff_step=1e-5, loss="huber", f_scale=HUBER_SCALE
    )
    theta = fit.theta.copy()
    theta[list(fit.free)] = result.x
    logger.info("fit of %d parameters: cost %.1f after %d evaluations", len(fit.free), result.cost, result.nfev)
    return InstrumentFit(theta, fit.scales, fit.free)


def fit_parameters(commands: np.ndarray, pixels: np.ndarray, free: tuple[int, ...] | None = None) -> InstrumentFit:
    """MAP fit of the parameters to rows (commands (N, 6), pixels (N, 3) from :func:`real_pixels`).

    First the camera and tape alone with unit scales; the residual RMS of that fit per
    component (u, v, disparity) becomes the scale of each residual; then the parameters
    ``free`` (default: all) from there.
    """
    free = tuple(range(len(PARAMETERS))) if free is None else tuple(free)
    first = refit(InstrumentFit(initial_vector(start_camera_pose()), np.ones(3), CAMERA_AND_TAPE), commands, pixels)
    scales = residual_rms(first.theta, commands, pixels)
    return refit(InstrumentFit(first.theta, scales, free), commands, pixels)


def residual_rms(theta: np.ndarray, commands: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """RMS of the pixel residuals (u, v, disparity), (3,) px."""
    return np.sqrt(np.mean((predict_pixels(theta, commands) - pixels) ** 2, axis=0))


def camera_residual_rms_mm(theta: np.ndarray, commands: np.ndarray, X: np.ndarray) -> np.ndarray:
    """RMS of the camera-frame residuals (x, y, z), (3,) mm."""
    return np.sqrt(np.mean((predict_camera_points(theta, commands) - X[:, :3]) ** 2, axis=0)) * 1e3


def bootstrap_sd(
    fit: InstrumentFit, commands: np.ndarray, pixels: np.ndarray, *, replicates: int, seed: int = 0, block: int = BOOTSTRAP_BLOCK
) -> np.ndarray:
    """sd of each parameter over a moving-block bootstrap of the rows, (n_parameters,).

    Each replicate draws ``len(rows) / block`` blocks of ``block`` contiguous rows with
    replacement, joins them in the drawn order and refits the free parameters from
    ``fit`` (with its residual scales). Parameters not fitted get sd 0.

    Raises:
        ValueError: ``replicates`` not an int in [2, ``MAX_BOOTSTRAP_REPLICATES``],
            ``block`` not an int in [1, rows], or a negative ``seed``.
    """
    replicates = check_int("replicates", replicates, 2, MAX_BOOTSTRAP_REPLICATES)
    n = len(commands)
    block = check_int("block", block, 1, max(n, 1))
    if n < block:
        raise ValueError(f"a block bootstrap of blocks of {block} rows needs at least {block} rows, got {n}")
    rng = np.random.default_rng(check_int("seed", seed, 0))
    estimates = []
    for k, rows in enumerate(block_bootstrap_rows(rng, n, block, replicates)):
        estimates.append(refit(fit, commands[rows], pixels[rows]).theta)
        logger.info("bootstrap replicate %d of %d done", k + 1, replicates)
    return np.std(np.array(estimates), axis=0, ddof=1)


def model_jitter_mm(theta: np.ndarray, commands: np.ndarray, X: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The fitted model's own jitter: the fidelity statistics of its noiseless predictions for the rows.

    Returns:
        (view-axis jitter, image-plane jitter per axis), mm, as
        :func:`~dvrk_gym.fidelity.statistics.fidelity_statistics` measures them on the real rows.
    """
    predicted = np.hstack([predict_camera_points(theta, commands), X[:, 3:]])
    statistics = fidelity_statistics(predicted, y, cross_validation=False)
    return statistics.view_axis_jitter_mm, statistics.image_plane_jitter_mm


def detector_plane_noise_mm(noise: DetectionNoise, depth_m: float) -> float:
    """RMS error per image-plane axis of a left detection with this noise, truncated to whole pixels, mm at depth_m."""
    per_axis_px = np.sqrt((1 - noise.outlier_probability) * noise.core_px**2 + noise.outlier_probability * noise.outlier_px**2 + 1 / 12)
    return float(per_axis_px * depth_m / paper.ENDOSCOPE_FOCAL_PX * 1e3)


def repeatability_from_jitter(real_plane_jitter_mm: float, model_plane_jitter_mm: float, detector_plane_mm: float) -> float:
    """The robot's repeatability (RMS tip scatter across the shaft, m) that the real rows' image-plane jitter leaves.

    Independent noise adds in quadrature to the jitter per axis: what the real rows show
    beyond the fitted model's own jitter over the same rows (:func:`model_jitter_mm`) and
    the detector's, per axis, times sqrt(2) for the two axes across the shaft, where the
    rotary joints move the tip (:func:`dvrk_gym.sim.robot.cables.repeatability_std`; the
    shaft is within about 10 degrees of the view axis). Measured on the real rows' own
    sequence, so that it is the robot's and not the exploration's: a simulated Phase I
    changes orientation more between consecutive rows than the real one did (median
    pitch change 11.7 against 7.2 degrees without the settle lag), which adds jitter of its own.
    """
    per_axis = np.sqrt(max(real_plane_jitter_mm**2 - model_plane_jitter_mm**2 - detector_plane_mm**2, 0.0))
    return float(per_axis * np.sqrt(2.0) * 1e-3)


@dataclass(frozen=True)
class MissMatch:
    """The detector's miss probability matched to the real rows' kept share.

    Attributes:
        miss_probability: the detector's chance of missing the tape in one image.
        sim_kept_share: kept share of a simulated Phase I without misses.
        real_kept_share: the real collection's kept share (1939 / 5256).
        sim_plane_jitter_mm: that simulation's image-plane jitter per axis (no
            repeatability), mm, for the record.
    """

    miss_probability: float
    sim_kept_share: float
    real_kept_share: float
    sim_plane_jitter_mm: float


def match_miss_probability(
    n_trajectories: int = paper.PHASE1_TRAJECTORIES, seed: int = 0, wrist_settle_lag: float | None = None
) -> MissMatch:
    """The detector's misses from the share of rows kept, with one simulated Phase I.

    Collects the paper's Phase I on the identified instrument (without repeatability;
    with the ``paper`` preset's settle lag, or ``wrist_settle_lag`` when given) with a
    detector that never misses (but searches only its boxes, as the authors' did). A miss
    in either camera loses a row, so the kept share goes as (1 - miss)^2: miss = 1 -
    sqrt(real share / simulated share). (The rows cannot tell a missed detection from one
    the 12 px gate threw out.)
    """
    config = dataclasses.replace(BIAS_PRESETS["paper"], repeatability_m=0.0)
    if wrist_settle_lag is not None:
        config = dataclasses.replace(config, wrist_settle_lag=wrist_settle_lag)
    env = CalibrationExplorationEnv(bias=config, max_steps=paper.PHASE1_POSES_PER_TRAJECTORY)
    try:
        world = env.world
        world.config = dataclasses.replace(world.config, marker_noise=dataclasses.replace(IDENTIFIED_MARKER_NOISE, miss_probability=0.0))
        data = collect_phase1(env, PaperExplorationPolicy(seed=seed), n_trajectories, seed=seed, progress=False)
    finally:
        env.close()
    kept = data.cleaned()
    sim_share = data.n_kept / data.n_raw
    real_share = paper.PHASE1_KEPT_SAMPLES / paper.PHASE1_RAW_SAMPLES
    miss = 1.0 - np.sqrt(min(real_share / sim_share, 1.0))
    jitter = fidelity_statistics(kept.X, kept.y, cross_validation=False).image_plane_jitter_mm
    return MissMatch(float(miss), float(sim_share), float(real_share), float(jitter))


SETTLE_LAG_GRID = (0.10, 0.15, 0.20, 0.25, 0.30, 0.35)
"""The settle lags :func:`match_settle_lag` collects at (the real rows' sequence suggests
0.2-0.4: ``benchmarks/fidelity_sequence.py``)."""


@dataclass(frozen=True)
class SettleLagMatch:
    """The wrist's settle lag matched to the real rows' same-position share.

    Attributes:
        wrist_settle_lag: where the simulated share first falls to the real one (:func:`first_crossing`).
        real_share: the real rows' same-position share.
        lags: the lags collected at.
        sim_shares: the simulated same-position share at each lag.
        sim_pitch_autocorrelations: the simulated pitch autocorrelation (lag 1) at each
            lag, for the record (the real rows: 0.27).
    """

    wrist_settle_lag: float
    real_share: float
    lags: tuple[float, ...]
    sim_shares: tuple[float, ...]
    sim_pitch_autocorrelations: tuple[float, ...]


def _check_lag_grid(lags: tuple[float, ...]) -> tuple[float, ...]:
    """``lags`` as floats, if they are one or more increasing settle lags, each in [0, 1)."""
    if not lags:
        raise ValueError("expected at least one settle lag, got none")
    values = tuple(check_float("settle lag", lag, low=0.0, high=1.0) for lag in lags)
    if values[-1] >= 1.0:
        raise ValueError(f"a settle lag is a fraction in [0, 1), got {values[-1]}")
    if any(b <= a for a, b in zip(values, values[1:])):
        raise ValueError(f"lags must increase, got {tuple(lags)}")
    return values


def first_crossing(lags: tuple[float, ...], shares: tuple[float, ...], target: float) -> float:
    """The lag where ``shares`` first fall to ``target``: linear between the two lags of the
    grid (increasing) around the crossing, to 0.01 (the first lag if its share is already
    at most the target).

    Raises:
        ValueError: lags and shares differ in length, lags do not increase, or no share
            falls to the target (the grid stops short).
    """
    if len(lags) != len(shares):
        raise ValueError(f"expected one share per lag, got {len(lags)} lags and {len(shares)} shares")
    _check_lag_grid(lags)
    for index, share in enumerate(shares):
        if share <= target:
            if index == 0:
                return float(lags[0])
            above, lag_above = shares[index - 1], lags[index - 1]
            crossing = round(float(lag_above + (lags[index] - lag_above) * (above - target) / (above - share)), 2)
            return min(max(crossing, float(lag_above)), float(lags[index]))
    raise ValueError(f"no lag in {lags} brings the share to {target:.4f} (the last gives {shares[-1]:.4f}); extend the grid")


def match_settle_lag(
    lags: tuple[float, ...] = SETTLE_LAG_GRID, n_trajectories: int = paper.PHASE1_TRAJECTORIES, seed: int = 0
) -> SettleLagMatch:
    """The reported pose's lag from how often consecutive rows report the same position.

    A robot that reports its command reports the same position whenever the protocol
    pauses at one position for several orientations (a simulated Phase I without a lag:
    0.52 of consecutive kept rows); the real rows do so 3% of the time, because the wrist
    stops short of each new orientation and the reported tip moves with it. Collects the
    paper's Phase I on the ``paper`` instrument (its detector and repeatability included)
    at each lag and returns the lag where the same-position share falls to the real one,
    linear between the grid's lags around it (:func:`first_crossing`).
    """
    lags = _check_lag_grid(tuple(lags))  # before the first collection: each takes about a minute
    n_trajectories = check_int("n_trajectories", n_trajectories, 1, MAX_TRAJECTORIES)
    seed = check_int("seed", seed, 0)
    real_X, real_y = load_paper_phase1()
    real_share = fidelity_statistics(real_X, real_y, cross_validation=False).same_position_share
    shares, correlations = [], []
    for lag in lags:
        config = dataclasses.replace(BIAS_PRESETS["paper"], wrist_settle_lag=float(lag))
        kept = run_paper_phase1(n_trajectories=n_trajectories, seed=seed, bias=config, progress=False).cleaned()
        statistics = fidelity_statistics(kept.X, kept.y, cross_validation=False)
        shares.append(statistics.same_position_share)
        correlations.append(statistics.pitch_autocorrelation)
        logger.info("settle lag %.2f: same-position share %.4f", lag, statistics.same_position_share)
    chosen = first_crossing(tuple(lags), tuple(shares), real_share)
    return SettleLagMatch(chosen, float(real_share), tuple(float(v) for v in lags), tuple(shares), tuple(correlations))
