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
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import run_paper_phase1
from dvrk_gym.fidelity.statistics import FidelityStatistics, fidelity_statistics, named_statistics
from dvrk_gym.fidelity.uncertainty import BOOTSTRAP_BLOCK_ROWS, BOOTSTRAP_REPLICATES, MAX_BOOTSTRAP_REPLICATES, statistic_standard_errors
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.utils.checks import check_int

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
        real_sd, sim_sd: the standard error of each value from its rows' sampling (a
            moving-block bootstrap, :mod:`~dvrk_gym.fidelity.uncertainty`), in its unit;
            None where none was estimated.
    """

    name: str
    real: float
    sim: float
    share: bool
    difference: float
    passed: bool
    tolerance: float
    real_sd: float | None = None
    sim_sd: float | None = None

    @property
    def z(self) -> float | None:
        """``(sim - real)`` in standard errors of that difference, ``sqrt(real_sd^2 + sim_sd^2)``
        (None without both, or when they are 0 or not finite): how far beyond the rows' own
        sampling the two lie, whatever the target's bound."""
        if self.real_sd is None or self.sim_sd is None:
            return None
        scale = math.hypot(self.real_sd, self.sim_sd)
        z = (self.sim - self.real) / scale if scale > 0 else math.nan
        return z if math.isfinite(z) else None

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


def compare(
    real: FidelityStatistics,
    sim: FidelityStatistics,
    real_kept_share: float,
    sim_kept_share: float,
    *,
    real_sd: Mapping[str, float] | None = None,
    sim_sd: Mapping[str, float] | None = None,
) -> list[ComparisonRow]:
    """Each statistic of both data sets with its verdict, in the issue's order.

    Args:
        real: the statistics of the real rows.
        sim: the statistics of the simulated rows.
        real_kept_share: kept rows over raw rows of the real collection.
        sim_kept_share: the same for the simulated collection.
        real_sd, sim_sd: standard errors by statistic name
            (:func:`~dvrk_gym.fidelity.uncertainty.statistic_standard_errors`); a name missing has none.
    """
    sim_values = {name: value for name, value, _ in named_statistics(sim, sim_kept_share)}
    rows = []
    for name, value, kind in named_statistics(real, real_kept_share):
        if name not in sim_values:  # a cross-validation run on one side only
            continue
        share, tolerance = _JUDGED[kind]
        row = _row(name, value, sim_values[name], share, tolerance)
        rows.append(dataclasses.replace(row, real_sd=(real_sd or {}).get(name), sim_sd=(sim_sd or {}).get(name)))
    return rows


_JUDGED: dict[str, tuple[bool, float | None]] = {
    "ratio": (False, None),
    "share": (True, None),
    "correlation": (True, CORRELATION_TOLERANCE),
    "median pitch": (True, PITCH_MEDIAN_TOLERANCE_DEG),
}
"""How each kind of statistic (:func:`~dvrk_gym.fidelity.statistics.named_statistics`) is judged: (by difference, its tolerance)."""


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
    *,
    bias: str = "paper",
    bias_seed: int = 0,
    wrist_settle_lag: float | None = None,
    n_trajectories: int = paper.PHASE1_TRAJECTORIES,
    seed: int = 0,
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX,
    progress: bool = True,
    bootstrap_replicates: int = BOOTSTRAP_REPLICATES,
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
        bootstrap_replicates: replicates of each side's standard errors
            (:func:`~dvrk_gym.fidelity.uncertainty.statistic_standard_errors`, seeded by ``seed``; about
            1.5 s each side at 200); 0: none.

    Raises:
        ValueError: when the simulation keeps too few rows for the statistics, or
            ``bootstrap_replicates`` is 1 or out of range.
    """
    if bootstrap_replicates != 0:
        check_int("bootstrap_replicates", bootstrap_replicates, 2, MAX_BOOTSTRAP_REPLICATES)
    if bias not in BIAS_PRESETS:
        raise ValueError(f"unknown bias preset {bias!r}; the presets are {sorted(BIAS_PRESETS)}")
    config = BIAS_PRESETS[bias]
    if wrist_settle_lag is not None:
        config = dataclasses.replace(config, wrist_settle_lag=wrist_settle_lag)
    data = run_paper_phase1(
        n_trajectories=n_trajectories,
        seed=seed,
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
    # at least four blocks a replicate: a short collection's blocks are shorter than a trajectory
    blocks = [max(1, min(BOOTSTRAP_BLOCK_ROWS, len(X) // 4)) for X in (real_X, kept.X)]
    sds: tuple[dict[str, float] | None, ...] = (None, None)
    if bootstrap_replicates:
        sds = tuple(
            statistic_standard_errors(X, y, replicates=bootstrap_replicates, block=block, seed=seed)
            for X, y, block in ((real_X, real_y, blocks[0]), (kept.X, kept.y, blocks[1]))
        )
    settings: dict[str, object] = {
        "bias": bias,
        "bias_seed": int(bias_seed),
        "wrist_settle_lag": float(config.wrist_settle_lag),
        "trajectories": int(n_trajectories),
        "seed": int(seed),
        "camera_resolution": [int(v) for v in camera_resolution],
        "bootstrap_replicates": int(bootstrap_replicates),
        "bootstrap_block_rows": {"real": blocks[0], "sim": blocks[1]} if bootstrap_replicates else None,
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
        rows=compare(real, sim, REAL_KEPT_SHARE, data.n_kept / data.n_raw, real_sd=sds[0], sim_sd=sds[1]),
    )
