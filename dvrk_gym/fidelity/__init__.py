"""Fidelity: how close a simulated instrument is to the real robot, statistic by statistic.

:mod:`~dvrk_gym.fidelity.statistics` computes the statistics of a Phase I data set (the
same code for the authors' real rows and for a simulated collection);
:mod:`~dvrk_gym.fidelity.uncertainty` estimates their standard errors from the rows;
:mod:`~dvrk_gym.fidelity.comparison` collects Phase I in simulation and judges each
statistic against the real one; :mod:`~dvrk_gym.fidelity.report` prints the table and
writes ``fidelity.json`` and ``fidelity.png``.

The names below are imported lazily (PEP 562), so importing the statistics does not pull in
matplotlib.
"""

from __future__ import annotations

from dvrk_gym.utils.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(  # PEP 562: each name imported from its module when first asked for
    __name__,
    {
        "FidelityStatistics": "statistics",
        "fidelity_statistics": "statistics",
        "rigid_residuals_camera": "statistics",
        "statistic_standard_errors": "uncertainty",
        "FidelityRun": "comparison",
        "compare": "comparison",
        "run_fidelity": "comparison",
        "format_table": "report",
        "write_report": "report",
    },
)
