"""Forest prediction: the calibrators' forests against scikit-learn's own ``predict``, on one batch.

Run: python benchmarks/bench_forest.py [--rows 10000] [--trees 100] [--repeats 15]

Two forests of 100 trees, fitted as the package fits them: the model search's forest
(``ForestCalibrator``, the authors' 1,939 real Phase I rows, 9 encoded features) and one
yaw group of the paper's Phase II residual forests (``ResidualForests``, 35 rows of 3
features: the forests a debridement policy queries). For each, the best of ``--repeats``
wall times (taken in turn) of ``RandomForestRegressor.predict`` and of the package's prediction
(:func:`~dvrk_gym.calibration.models.forests.forest_predict`, alone and through the
calibrator with its input checks and encoding) on a ``--rows`` batch and on one row, their
ratio (above 1: the package is faster), and whether the predictions are identical bit for
bit. One thread (scikit-learn's ``n_jobs=None``). Takes about 30 s.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.models.features import PAPER_YAWS_RAD, encode_euler
from dvrk_gym.calibration.models.forests import ForestCalibrator, ResidualForests, forest_predict
from dvrk_gym.cli.options import check_flag_bounds

PHASE2_CIRCLES = 35  # rows of one yaw group of Phase II


def _best_s(calls: list[Callable[[], object]], repeats: int) -> list[float]:
    """The shortest of ``repeats`` wall times of each call, seconds: one warm-up call each, then the calls
    taken in turn, so that other jobs on the machine slow each of them alike."""
    times: list[list[float]] = [[] for _ in calls]
    for call in calls:
        call()
    for _ in range(repeats):
        for call, taken in zip(calls, times):
            start = time.perf_counter()
            call()
            taken.append(time.perf_counter() - start)
    return [min(taken) for taken in times]


def _report(name: str, forest, features: np.ndarray, wrapped: Callable[[np.ndarray], np.ndarray], inputs: np.ndarray, repeats: int) -> None:
    identical = np.array_equal(forest_predict(forest, features), forest.predict(features))
    print(f"{name}: {len(forest.estimators_)} trees, {forest.n_features_in_} features; identical to scikit-learn's predict: {identical}")
    print(f"  {'rows':>6}{'sklearn ms':>12}{'forest_predict ms':>19}{'ratio':>8}{'calibrator ms':>15}{'ratio':>8}")
    for rows in (len(features), 1):
        sklearn_s, ours_s, wrapped_s = _best_s(
            [
                lambda rows=rows: forest.predict(features[:rows]),
                lambda rows=rows: forest_predict(forest, features[:rows]),
                lambda rows=rows: wrapped(inputs[:rows]),
            ],
            repeats,
        )
        print(
            f"  {rows:>6}{1e3 * sklearn_s:>12.2f}{1e3 * ours_s:>19.2f}{sklearn_s / ours_s:>8.2f}"
            f"{1e3 * wrapped_s:>15.2f}{sklearn_s / wrapped_s:>8.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=10_000, help="rows of the batch (default: %(default)s)")
    parser.add_argument("--trees", type=int, default=100, help="trees of each forest (default: %(default)s)")
    parser.add_argument("--repeats", type=int, default=15, help="timed calls of each, the best kept (default: %(default)s)")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"rows": (1, 10_000_000), "trees": (1, 10_000), "repeats": (1, 10_000)})
    rng = np.random.default_rng(0)

    X, y = load_paper_phase1()
    search_forest = ForestCalibrator(trees=args.trees, seed=0).fit(X, y)
    batch = X[rng.integers(0, len(X), args.rows)]
    _report(
        "model search forest (real Phase I rows)", search_forest.forest_, encode_euler(batch), search_forest.predict, batch, args.repeats
    )

    base = rng.uniform([0.005, 0.011, -0.17], [0.07, 0.074, -0.158], (PHASE2_CIRCLES, 3))  # predicted base positions, m
    residual = rng.normal(0.0, 1e-3, (PHASE2_CIRCLES, 3))
    forests = ResidualForests(trees=args.trees, seed=0).fit(base, np.zeros(PHASE2_CIRCLES), residual)
    queries = rng.uniform(base.min(axis=0), base.max(axis=0), (args.rows, 3))
    yaw = np.full(args.rows, PAPER_YAWS_RAD[2])
    assert forests.forests_ is not None and forests.forests_[2] is not None
    _report(
        "Phase II residual forest (yaw 0)",
        forests.forests_[2],
        queries,
        lambda rows: forests.predict(rows, yaw[: len(rows)]),
        queries,
        args.repeats,
    )
    print("ratio: scikit-learn's time over the package's (above 1: the package is faster)")


if __name__ == "__main__":
    main()
