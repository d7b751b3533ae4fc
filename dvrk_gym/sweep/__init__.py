"""Sweeps: the paper's calibration over a grid of instruments, calibrators and seeds.

>>> from dvrk_gym.sweep import LocalExecutor, SweepSettings, run_sweep
>>> settings = SweepSettings(bias_seeds=(0, 1, 2, 3, 4), calibrators=("rbt", "dnn", "dnn+rf"), seeds=(0,))
>>> with LocalExecutor(workers=2) as executor:  # doctest: +SKIP
...     result = run_sweep(settings, "dvrk_gym_out/sweep", executor)
>>> result.csv  # doctest: +SKIP
PosixPath('dvrk_gym_out/sweep/sweep.csv')

On a Dask cluster, ``DaskExecutor("tcp://host:8786")`` from :mod:`dvrk_gym.parallel.dask_executor`
(the ``dask`` extra) takes the place of ``LocalExecutor``, with the same numbers. The
executors live in :mod:`dvrk_gym.parallel` (``dvrk-gym reproduce`` runs on them too) and
are named here as well.
"""

from dvrk_gym.parallel.executors import Executor, LocalExecutor, Outcome
from dvrk_gym.sweep.grid import CALIBRATORS, SweepSettings, Unit, parse_calibrators, parse_int_list
from dvrk_gym.sweep.run import SweepError, SweepResult, run_sweep
from dvrk_gym.sweep.table import COLUMN_DOCS, COLUMNS, format_rows, plot_errors, sweep_rows, write_csv
from dvrk_gym.sweep.unit import run_unit

__all__ = [
    "CALIBRATORS",
    "COLUMNS",
    "COLUMN_DOCS",
    "Executor",
    "LocalExecutor",
    "Outcome",
    "SweepError",
    "SweepResult",
    "SweepSettings",
    "Unit",
    "format_rows",
    "parse_calibrators",
    "parse_int_list",
    "plot_errors",
    "run_sweep",
    "run_unit",
    "sweep_rows",
    "write_csv",
]
