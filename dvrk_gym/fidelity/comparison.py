"""A simulated instrument against the real robot: Phase I collected in simulation, the
statistics of both, and a verdict per statistic against the issue 15 targets.

Targets: every statistic within ``RELATIVE_TOLERANCE`` (25%) of the real value, every
share (a fraction of rows or of residual energy) within ``SHARE_TOLERANCE`` (0.06) of it,
the pitch autocorrelation within ``CORRELATION_TOLERANCE`` (0.1) of it, and every per-yaw
median pitch within ``PITCH_MEDIAN_TOLERANCE_DEG`` (5 degrees: a quarter
of the half-range of the paper's pitches, -15 to 25 degrees) of it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import run_paper_phase1
from dvrk_gym.fidelity.statistics import PAPER_YAWS_DEG, FidelityStatistics, fidelity_statistics
from dvrk_gym.sim.robot.bias import BIAS_PRESETS

__all__ = [
    "RELATIVE_TOLERANCE",
    "SHARE_TOLERANCE",
    "PITCH_MEDIAN_TOLERANCE_DEG",
    "CORRELATION_TOLERANCE",
    "ComparisonRow",
    "FidelityRun",
    "compare",
    "run_fidelity",
]

RELATIVE_TOLERANCE = 0.25
"""A statistic passes when |sim / real - 1| is at most this."""
SHARE_TOLERANCE = 0.06
"""A share passes when |sim - real| is at most this (absolute)."""
PITCH_MEDIAN_TOLERANCE_DEG = 5.0
"""A per-yaw median pitch passes when |sim - real| is at most this, degrees (absolute)."""
CORRELATION_TOLERANCE = 0.1
"""A correlation passes when |sim - real| is at most this (absolute): about four standard
errors of a correlation over 1,939 rows."""
REAL_KEPT_SHARE = paper.PHASE1_KEPT_SAMPLES / paper.PHASE1_RAW_SAMPLES
"""The real Phase I's kept share of raw rows (1939 of 5256)."""


@dataclass(frozen=True)
class ComparisonRow:
    """One statistic, real against simulated.

    Attributes:
        name: the statistic, with its unit (``"rigid residual RMS (mm)"``).
        real: its value on the authors' rows.
        sim: its value on the simulated rows.
        share: True when it is judged by absolute difference (a share, a correlation or a
            per-yaw median pitch); else by ratio.
        difference: ``sim - real`` for a share, ``sim / real`` otherwise (nan if real is 0).
        passed: whether ``difference`` meets the target.
        tolerance: the target's bound: on ``|difference|`` for a share, on
            ``|difference - 1|`` for a ratio (``RELATIVE_TOLERANCE``).
    """

    name: str
    real: float
    sim: float
    share: bool
    difference: float
    passed: bool
    tolerance: float

    @property
    def target(self) -> str:
        """The target in words: ``"|diff| <= 0.06"`` or ``"ratio 0.75-1.25"``."""
        if self.share:
            return f"|diff| <= {self.tolerance:g}"
        return f"ratio {1 - self.tolerance:.2f}-{1 + self.tolerance:.2f}"


def _row(name: str, real: float, sim: float, share: bool, tolerance: float | None = None) -> ComparisonRow:
    """``tolerance``: a share's bound (default ``SHARE_TOLERANCE``); a ratio's is ``RELATIVE_TOLERANCE``."""
    if share:
        tolerance = SHARE_TOLERANCE if tolerance is None else tolerance
        difference = sim - real
        passed = bool(np.isfinite(difference) and abs(difference) <= tolerance)
    else:
        if tolerance is not None:
            raise ValueError(f"{name}: a ratio is judged by RELATIVE_TOLERANCE, not by a tolerance of its own")
        tolerance = RELATIVE_TOLERANCE
        difference = sim / real if real != 0 else float("nan")
        passed = bool(np.isfinite(difference) and abs(difference - 1.0) <= tolerance)
    return ComparisonRow(
        name=name, real=float(real), sim=float(sim), share=share, difference=float(difference), passed=bool(passed), tolerance=tolerance
    )


def compare(real: FidelityStatistics, sim: FidelityStatistics, real_kept_share: float, sim_kept_share: float) -> list[ComparisonRow]:
    """Each statistic of both data sets with its verdict, in the issue's order.

    Args:
        real: the statistics of the real rows.
        sim: the statistics of the simulated rows.
        real_kept_share: kept rows over raw rows of the real collection.
        sim_kept_share: the same for the simulated collection.
    """
    rows = [
        _row("rigid residual RMS (mm)", real.rigid_residual_rms_mm, sim.rigid_residual_rms_mm, False),
        _row("residual share along view axis", real.view_axis_share, sim.view_axis_share, True),
        _row("jitter along view axis (mm)", real.view_axis_jitter_mm, sim.view_axis_jitter_mm, False),
        _row("jitter in image plane (mm)", real.image_plane_jitter_mm, sim.image_plane_jitter_mm, False),
        _row("same reported position, consecutive rows (share)", real.same_position_share, sim.same_position_share, True),
        _row("pitch autocorrelation, consecutive rows", real.pitch_autocorrelation, sim.pitch_autocorrelation, True, CORRELATION_TOLERANCE),
        _row("tilt of the rows' plane in the base frame (deg)", real.plane_tilt_deg, sim.plane_tilt_deg, False),
    ]
    for yaw, real_fraction, sim_fraction in zip(PAPER_YAWS_DEG, real.kept_fraction_per_yaw, sim.kept_fraction_per_yaw):
        rows.append(_row(f"kept rows at yaw {yaw:+.0f} (share)", real_fraction, sim_fraction, True))
    rows += [
        _row("kept share of raw rows", real_kept_share, sim_kept_share, True),
        _row("pitch of kept rows, 5th pct (deg)", real.pitch_p5_deg, sim.pitch_p5_deg, False),
        _row("pitch of kept rows, 95th pct (deg)", real.pitch_p95_deg, sim.pitch_p95_deg, False),
    ]
    for yaw, real_pitch, sim_pitch in zip(PAPER_YAWS_DEG, real.pitch_median_per_yaw_deg, sim.pitch_median_per_yaw_deg):
        rows.append(_row(f"median pitch at yaw {yaw:+.0f} (deg)", real_pitch, sim_pitch, True, PITCH_MEDIAN_TOLERANCE_DEG))
    if real.cv_linear_mm2 is not None and sim.cv_linear_mm2 is not None:
        rows.append(_row("contiguous 10-fold CV, linear (mm^2)", real.cv_linear_mm2, sim.cv_linear_mm2, False))
    if real.cv_forest_mm2 is not None and sim.cv_forest_mm2 is not None:
        rows.append(_row("contiguous 10-fold CV, forest (mm^2)", real.cv_forest_mm2, sim.cv_forest_mm2, False))
    return rows


@dataclass(frozen=True)
class FidelityRun:
    """The real rows, a simulated collection's kept rows, their statistics and the verdicts.

    Attributes:
        settings: how the simulation was collected (bias, bias_seed, trajectories, seed,
            camera_resolution).
        real_X, real_y: the authors' rows (m, rad; m).
        sim_X, sim_y: the simulation's kept rows (m, rad; m), in collection order.
        sim_raw_rows: the simulation's raw rows (before cleaning).
        real: statistics of the real rows.
        sim: statistics of the simulated rows.
        rows: the comparison (:func:`compare`).
    """

    settings: dict[str, object]
    real_X: np.ndarray
    real_y: np.ndarray
    sim_X: np.ndarray
    sim_y: np.ndarray
    sim_raw_rows: int
    real: FidelityStatistics
    sim: FidelityStatistics
    rows: list[ComparisonRow]

    @property
    def passed(self) -> int:
        """How many statistics meet their target."""
        return sum(row.passed for row in self.rows)


def run_fidelity(
    bias: str = "paper",
    bias_seed: int = 0,
    wrist_settle_lag: float | None = None,
    n_trajectories: int = paper.PHASE1_TRAJECTORIES,
    seed: int = 0,
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX,
    progress: bool = True,
) -> FidelityRun:
    """Collect Phase I in simulation and compare it, statistic by statistic, with the real rows.

    Args:
        bias: the cable bias preset of the simulated instrument.
        bias_seed: which instrument.
        wrist_settle_lag: the preset with this ``BiasConfig.wrist_settle_lag`` instead
            of its own (the fraction of each wrist step the motors leave undone, in
            [0, 1); ``paper``'s is 0.19); None: the preset's.
        n_trajectories: Phase I trajectories (the paper: 57; about 35-50 s at 1920 x 1080).
        seed: seeds the exploration and the episodes, and the cross-validated forest.
        camera_resolution: the endoscope's image size (width, height), pixels.
        progress: show a progress bar.

    Raises:
        ValueError: when the simulation keeps too few rows for the statistics.
    """
    if bias not in BIAS_PRESETS:
        raise ValueError(f"unknown bias preset {bias!r}; the presets are {sorted(BIAS_PRESETS)}")
    config = BIAS_PRESETS[bias]
    if wrist_settle_lag is not None:
        config = dataclasses.replace(config, wrist_settle_lag=wrist_settle_lag)
    data = run_paper_phase1(
        n_trajectories,
        seed,
        bias=config,
        bias_seed=bias_seed,
        camera_resolution=(int(camera_resolution[0]), int(camera_resolution[1])),
        progress=progress,
    )
    kept = data.cleaned()
    real_X, real_y = load_paper_phase1()
    real = fidelity_statistics(real_X, real_y, seed=seed)
    try:
        sim = fidelity_statistics(kept.X, kept.y, seed=seed)
    except ValueError as error:
        raise ValueError(
            f"no statistics of the simulated Phase I's {len(kept.y)} kept rows (of {len(data.y)}): {error}; "
            "with few rows kept, collect more trajectories or at a higher camera resolution"
        ) from error
    settings: dict[str, object] = {
        "bias": bias,
        "bias_seed": int(bias_seed),
        "wrist_settle_lag": float(config.wrist_settle_lag),
        "trajectories": int(n_trajectories),
        "seed": int(seed),
        "camera_resolution": [int(v) for v in camera_resolution],
    }
    return FidelityRun(
        settings=settings,
        real_X=real_X,
        real_y=real_y,
        sim_X=kept.X,
        sim_y=kept.y,
        sim_raw_rows=data.n_raw,
        real=real,
        sim=sim,
        rows=compare(real, sim, REAL_KEPT_SHARE, data.n_kept / data.n_raw),
    )
