"""How much a fidelity statistic moves with the rows it was measured on: a moving-block bootstrap.

The real Phase I is one collection of 57 trajectories, and a simulated one is another; each
statistic of :func:`~dvrk_gym.fidelity.statistics.fidelity_statistics` would come out
otherwise from another collection of the same robot. :func:`statistic_standard_errors` estimates that
spread from the rows themselves: each replicate joins ``len(rows) // block`` blocks of
``block`` consecutive rows drawn with replacement (about one trajectory a block, so the
order within a trajectory, which the jitter, the same-position share and the pitch
autocorrelation read, is kept), and the standard error of a statistic is its standard
deviation over the replicates. The cross-validations are left out (about 7 s a replicate),
as is the kept share of raw rows (the raw rows are not resampled).

On the authors' 1,939 rows (``dvrk-gym fidelity`` prints them as ``real sd``), for example,
the median pitch at yaw 90 has a standard error of 1.0 degree (1.7 at yaw -90), the
pitch autocorrelation 0.03 and the rigid residual RMS 0.25 mm.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from dvrk_gym.fidelity.statistics import fidelity_statistics, named_statistics
from dvrk_gym.utils.checks import check_int

__all__ = ["BOOTSTRAP_BLOCK_ROWS", "BOOTSTRAP_REPLICATES", "MAX_BOOTSTRAP_REPLICATES", "block_bootstrap_rows", "statistic_standard_errors"]

BOOTSTRAP_BLOCK_ROWS = 34
"""Rows per block: the authors' kept rows per trajectory (1,939 over 57)."""
BOOTSTRAP_REPLICATES = 200
"""Replicates unless asked otherwise (about 5 ms each on 1,939 rows): the standard error of
a standard deviation estimated from 200 draws is 5% of it."""
MAX_BOOTSTRAP_REPLICATES = 100_000
"""The most replicates :func:`statistic_standard_errors` runs."""


def block_bootstrap_rows(rng: np.random.Generator, rows: int, block: int, replicates: int) -> Iterator[np.ndarray]:
    """Each replicate's row indices: ``rows // block`` blocks of ``block`` consecutive rows,
    their starts drawn with replacement from ``rng``, joined in the drawn order."""
    for starts in rng.integers(0, rows - block + 1, size=(replicates, rows // block)):
        yield (starts[:, None] + np.arange(block)).ravel()


def statistic_standard_errors(
    X: np.ndarray, y: np.ndarray, *, replicates: int = BOOTSTRAP_REPLICATES, block: int = BOOTSTRAP_BLOCK_ROWS, seed: int = 0
) -> dict[str, float]:
    """The standard error of each statistic of the fidelity table, by its name
    (:func:`~dvrk_gym.fidelity.statistics.named_statistics`), in the statistic's unit.

    Args:
        X: (N, 6) kept rows: camera-frame marker position (m), reported yaw, pitch, roll
            (rad), in collection order.
        y: (N, 3) reported base position (m).
        replicates: bootstrap replicates, in [2, ``MAX_BOOTSTRAP_REPLICATES``].
        block: consecutive rows per block, in [1, N].
        seed: seeds the draw of the blocks.

    Returns:
        ``{name: sd}`` for every statistic but the cross-validations and the kept share; nan
        where fewer than two replicates gave the statistic a value (a yaw without rows has
        no median pitch; a replicate too small for the statistics gives none).

    Raises:
        ValueError: bad rows (as :func:`~dvrk_gym.fidelity.statistics.fidelity_statistics`),
            ``replicates`` or ``block`` out of range, a negative ``seed``.
    """
    replicates = check_int("replicates", replicates, 2, MAX_BOOTSTRAP_REPLICATES)
    whole = fidelity_statistics(X, y, cross_validation=False)  # the rows' own checks, before any draw
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    block = check_int("block", block, 1, len(X))
    rng = np.random.default_rng(check_int("seed", seed, 0))
    draws: dict[str, list[float]] = {}
    for rows in block_bootstrap_rows(rng, len(X), block, replicates):
        try:
            statistics = fidelity_statistics(X[rows], y[rows], cross_validation=False)
        except ValueError:  # a replicate without a consecutive pair for the jitter, say
            continue
        for name, value, _ in named_statistics(statistics):
            draws.setdefault(name, []).append(value)
    sds = {}
    for name, _, _ in named_statistics(whole):
        values = np.asarray(draws.get(name, []), dtype=float)
        values = values[np.isfinite(values)]
        sds[name] = float(np.std(values, ddof=1)) if values.size >= 2 else float("nan")
    return sds
