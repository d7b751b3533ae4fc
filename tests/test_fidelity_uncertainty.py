"""The fidelity statistics' standard errors: a moving-block bootstrap of the rows, and z."""

import math

import numpy as np
import pytest

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity.comparison import ComparisonRow, compare
from dvrk_gym.fidelity.statistics import fidelity_statistics, named_statistics
from dvrk_gym.fidelity.uncertainty import statistic_standard_errors

REAL_X, REAL_Y = load_paper_phase1()


def test_the_same_seed_gives_the_same_standard_errors_and_every_statistic_but_the_cvs_has_one():
    first = statistic_standard_errors(REAL_X, REAL_Y, replicates=40, seed=3)
    assert first == statistic_standard_errors(REAL_X, REAL_Y, replicates=40, seed=3)
    assert first != statistic_standard_errors(REAL_X, REAL_Y, replicates=40, seed=4)
    names = [name for name, _, _ in named_statistics(fidelity_statistics(REAL_X, REAL_Y, cross_validation=False))]
    assert list(first) == names and len(names) == 19  # 22 less the kept share and the two CVs
    assert all(math.isfinite(sd) and sd > 0 for sd in first.values()), first


def test_four_times_the_rows_halve_the_standard_errors():
    """The spread of a statistic over resamples falls as one over the root of the rows: the
    same rows four times over (whole blocks, in order) give half the standard error."""
    once = statistic_standard_errors(REAL_X, REAL_Y, replicates=200, seed=0)
    four = statistic_standard_errors(np.tile(REAL_X, (4, 1)), np.tile(REAL_Y, (4, 1)), replicates=200, seed=0)
    for name in ("rigid residual RMS (mm)", "kept rows at yaw +0 (share)", "pitch of kept rows, 95th pct (deg)"):
        assert 0.35 < four[name] / once[name] < 0.7, (name, once[name], four[name])


def test_a_statistic_that_cannot_vary_has_no_spread():
    """Every row at one yaw: every resample keeps all of them there, so its share never moves."""
    X = REAL_X.copy()
    X[:, 3] = 0.0
    sds = statistic_standard_errors(X, REAL_Y, replicates=20, seed=0)
    assert sds["kept rows at yaw +0 (share)"] == 0.0 and math.isnan(sds["median pitch at yaw +90 (deg)"])


@pytest.mark.parametrize(("keywords", "word"), [({"replicates": 1}, "replicates"), ({"block": 5000}, "block"), ({"seed": -1}, "seed")])
def test_bad_bootstrap_settings_are_refused(keywords, word):
    with pytest.raises(ValueError, match=word):
        statistic_standard_errors(REAL_X, REAL_Y, **keywords)


def test_z_is_the_difference_over_both_standard_errors_and_compare_carries_them():
    row = ComparisonRow("a (mm)", real=2.0, sim=5.0, share=True, difference=3.0, passed=True, tolerance=5.0, real_sd=3.0, sim_sd=4.0)
    assert row.z == pytest.approx(3.0 / 5.0)
    assert ComparisonRow("a (mm)", 2.0, 5.0, True, 3.0, True, 5.0, real_sd=3.0).z is None
    assert ComparisonRow("a (mm)", 2.0, 5.0, True, 3.0, True, 5.0, real_sd=0.0, sim_sd=0.0).z is None
    stats = fidelity_statistics(REAL_X, REAL_Y, cross_validation=False)
    rows = compare(stats, stats, 0.37, 0.37, real_sd={"rigid residual RMS (mm)": 0.5}, sim_sd={"rigid residual RMS (mm)": 0.25})
    first = rows[0]
    assert (first.name, first.real_sd, first.sim_sd, first.z) == ("rigid residual RMS (mm)", 0.5, 0.25, 0.0)
    assert all(row.real_sd is None for row in rows[1:])
