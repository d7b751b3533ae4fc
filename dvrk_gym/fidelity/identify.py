"""Identify the paper's instrument from the authors' real Phase I rows: fit, held-out check, uncertainty.

Three steps, each on a training part of the rows (the first ``TRAIN_FRACTION`` in
collection order) and judged on the held-out rest:

1. The deterministic parameters (:data:`~dvrk_gym.fidelity.instrument_model.PARAMETERS`:
   camera pose and depth scale, tape position, homing offsets, cable stretch, backlash) by
   maximum a posteriori least squares (``scipy.optimize.least_squares``) on the pixel
   residuals of every row (a Huber loss) and the parameters' Gaussian priors (plain
   squares): left u, v and the disparity, each divided by its RMS after a first fit of the
   camera and tape alone.
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
   of lags (:func:`dvrk_gym.fidelity.settle_lag.match_settle_lag`). It runs before the
   misses are matched again: the lag changes which orientations keep their tape in view.

``python benchmarks/identify_instrument.py`` runs it all. :mod:`dvrk_gym.sim.identified`
holds what it printed before three mends (Gaussian priors, the stereo depth's share of the
detector's noise, the camera's rotation fitted as a turn of its start); what it prints
now is a candidate, set out in docs/fidelity.md ("The identification mended").
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from dvrk_gym import paper
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, collect_phase1
from dvrk_gym.envs.exploration import CalibrationExplorationEnv
from dvrk_gym.fidelity.instrument_model import PARAMETERS, initial_vector, predict_camera_points, predict_pixels
from dvrk_gym.fidelity.statistics import fidelity_statistics
from dvrk_gym.fidelity.uncertainty import block_bootstrap_rows
from dvrk_gym.sim.endoscope.camera import WORKSPACE_CENTER_M
from dvrk_gym.sim.endoscope.noise import IDENTIFIED_MARKER_NOISE
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.utils.checks import check_int

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
    "huber_residuals",
    "CAMERA_ROTATION",
    "start_values",
    "theta_of",
    "residual_rms",
    "bootstrap_sd",
    "model_jitter_mm",
    "repeatability_from_jitter",
    "MissMatch",
    "match_miss_probability",
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


def huber_residuals(scaled: np.ndarray, scale: float = HUBER_SCALE) -> np.ndarray:
    """Residuals (dimensionless) whose sum of squares is the Huber loss of ``scaled``.

    Each r becomes ``sign(r) c sqrt(rho((r / c)^2))`` with ``c = scale`` and scipy's Huber
    ``rho(z) = z`` up to 1, ``2 sqrt(z) - 1`` beyond: unchanged within ``c``, growing as the
    square root of ``|r|`` past it. A plain least-squares fit of these is the Huber fit of
    ``scaled`` alone, so the priors beside them stay quadratic (Gaussian).
    """
    z = (np.asarray(scaled, dtype=float) / scale) ** 2
    rho = np.where(z <= 1.0, z, 2.0 * np.sqrt(np.maximum(z, 1.0)) - 1.0)
    return np.sign(scaled) * scale * np.sqrt(rho)


CAMERA_ROTATION = (0, 1, 2)
"""Indices of the camera's rotation vector: a fit moves them together, as a turn of the start's camera (:func:`theta_of`)."""


def _check_free(free: tuple[int, ...]) -> tuple[int, ...]:
    """``free`` if it frees the camera's rotation whole or not at all (ValueError otherwise)."""
    freed = set(free) & set(CAMERA_ROTATION)
    if freed and freed != set(CAMERA_ROTATION):
        raise ValueError(f"free = {free}; the camera's rotation {CAMERA_ROTATION} is fitted whole or not at all")
    return free


def theta_of(free_values: np.ndarray, fit: InstrumentFit) -> np.ndarray:
    """The parameter vector a fit's free values stand for, from ``fit.theta``.

    The camera's rotation, when free, is a rotation vector *of a turn of the start's
    camera* (zero at the start, where it is well conditioned). Fitted as the absolute
    rotation vector of a camera looking down (near a half turn), fits stopped at points
    that hung on the start's last bit (two starts 6e-17 apart: cameras about 90 mm apart);
    why is not pinned down (that map is not singular there, though it stretches a turn
    about two axes 1.5 times as much as about the third).
    """
    _check_free(fit.free)
    theta = fit.theta.copy()
    theta[list(fit.free)] = free_values
    if CAMERA_ROTATION[0] in fit.free:
        turn = Rotation.from_rotvec(theta[list(CAMERA_ROTATION)])
        theta[list(CAMERA_ROTATION)] = (Rotation.from_rotvec(fit.theta[list(CAMERA_ROTATION)]) * turn).as_rotvec()
    return theta


def start_values(fit: InstrumentFit) -> np.ndarray:
    """The free values a fit starts from (:func:`theta_of` gives back ``fit.theta``): each
    free parameter's value, and no turn yet of the camera's rotation.

    Raises:
        ValueError: ``fit.free`` frees only part of the camera's rotation.
    """
    free = _check_free(fit.free)
    return np.where(np.isin(free, CAMERA_ROTATION), 0.0, fit.theta[list(free)])


def _residuals(free_values: np.ndarray, fit: InstrumentFit, commands: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    theta = theta_of(free_values, fit)
    scaled = ((predict_pixels(theta, commands) - pixels) / fit.scales).ravel()
    return np.concatenate([huber_residuals(scaled), prior_residuals(theta, fit.free)])


def prior_residuals(theta: np.ndarray, free: tuple[int, ...]) -> np.ndarray:
    """The priors' terms of the fit's residuals: each free parameter that has a prior over its sd."""
    return np.array([theta[i] / PARAMETERS[i].prior_sd for i in free if PARAMETERS[i].prior_sd is not None], dtype=float)


def refit(fit: InstrumentFit, commands: np.ndarray, pixels: np.ndarray) -> InstrumentFit:
    """MAP fit of the parameters ``fit.free`` to rows (commands (N, 6) rad / m, pixels (N, 3)
    px), starting from ``fit.theta`` with its residual scales; the others keep their values.

    The pixel residuals take the Huber loss (:func:`huber_residuals`: the detector's
    outliers), the priors a plain square: their penalty is Gaussian however far out a
    parameter lies (scipy's ``loss="huber"`` on both would make them linear past two sds).
    The camera's rotation is fitted as a turn of ``fit.theta``'s (:func:`theta_of`)."""
    result = least_squares(_residuals, start_values(fit), args=(fit, commands, pixels), x_scale="jac", diff_step=1e-5)
    theta = theta_of(result.x, fit)
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
    ``fit`` (with its residual scales). Parameters not fitted get sd 0. The camera's
    rotation (:data:`CAMERA_ROTATION`) is taken as each replicate's turn of ``fit``'s
    camera, rad about the fitted camera's axes: the rotation vector's own components stretch
    a turn by up to 1.5 times near a half turn and mix its axes.

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
        theta = refit(fit, commands[rows], pixels[rows]).theta
        turn = Rotation.from_rotvec(fit.theta[list(CAMERA_ROTATION)]).inv() * Rotation.from_rotvec(theta[list(CAMERA_ROTATION)])
        theta[list(CAMERA_ROTATION)] = turn.as_rotvec()
        estimates.append(theta)
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


def repeatability_from_jitter(real_plane_jitter_mm: float, model_plane_jitter_mm: float, detector_plane_mm: float) -> float:
    """The robot's repeatability (RMS tip scatter across the shaft, m) that the real rows' image-plane jitter leaves.

    Independent noise adds in quadrature to the jitter per axis: what the real rows show
    beyond the fitted model's own jitter over the same rows (:func:`model_jitter_mm`) and
    the detector's (:func:`~dvrk_gym.fidelity.detector_noise.plane_noise_mm`: the left
    pixel's error and the stereo depth's, which reaches camera x and y by x / z), per axis,
    times sqrt(2) for the two axes across the shaft, where the
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
