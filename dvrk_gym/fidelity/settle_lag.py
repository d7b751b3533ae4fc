"""The reported pose's lag (``BiasConfig.wrist_settle_lag``), matched to how often the real rows repeat a position.

Step 4 of the identification (:mod:`dvrk_gym.fidelity.identify`): simulated Phase I
collections of the ``paper`` instrument over a grid of lags, and the lag where their
same-position share of consecutive rows falls to the real rows'.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import MAX_TRAJECTORIES, run_paper_phase1
from dvrk_gym.fidelity.statistics import fidelity_statistics
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.utils.checks import check_float, check_int

__all__ = ["SETTLE_LAG_GRID", "SettleLagMatch", "first_crossing", "match_settle_lag"]

logger = logging.getLogger(__name__)

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
