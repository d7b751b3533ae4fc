"""What one unit of a sweep computes: the paper's calibration on one instrument, and its table.

:func:`run_unit` runs the calibration pipeline (Phase I, the rigid body fit, the DNN,
Phase II, the residual forests) in a temporary folder (:data:`SCRATCH_PREFIX`) and benchmarks each calibrator on
the 35 circles in the paper's six settings, exactly as ``dvrk-gym evaluate`` does with the
same settings. It returns plain numbers, so a worker on another machine needs no shared
disk: the process that runs the sweep writes them. It seeds itself and runs with one torch
thread, so its numbers do not depend on where it runs.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import gymnasium as gym

from dvrk_gym.calibration.benchmark import calibration_table, paper_table_rules, table_summary
from dvrk_gym.calibration.pipeline import BENCHMARK_SEED_OFFSET, PipelineConfig, run_calibration
from dvrk_gym.sweep.grid import CALIBRATORS, METHOD_NAMES
from dvrk_gym.utils.parent_watch import ScratchFolder
from dvrk_gym.utils.torch_threads import torch_threads

SCRATCH_PREFIX = "dvrk_gym_sweep_"
"""The unit's pipeline folders, in the worker's temporary folder: ``dvrk_gym_sweep_<host>_<pid>_*``
(:class:`~dvrk_gym.utils.parent_watch.ScratchFolder`: those of a worker killed meanwhile are
deleted by the next unit that starts on that host)."""


def _errors(summary: dict[str, Any]) -> dict[str, Any]:
    """One calibrator's summary rows as the unit result keeps them (mm and pixels)."""
    every = summary.pop("all settings")
    return {
        "mean_mm": every["mm"]["mean"],
        "sem_mm": every["mm"]["sem"],
        "mean_px": every["pixel"]["mean"],
        "sem_px": every["pixel"]["sem"],
        "settings": {label: {"mean_mm": row["mm"]["mean"], "mean_px": row["pixel"]["mean"]} for label, row in summary.items()},
    }


def run_unit(config: PipelineConfig) -> dict[str, Any]:
    """Calibrate one instrument with one seed and benchmark all three calibrators.

    Args:
        config: the pipeline's settings (its ``bias_seed`` and ``seed`` name the unit).

    Returns:
        JSON-able: ``{"config": ..., "phase1": {"raw", "kept"}, "stages_s": {...},
        "calibrators": {name: {"mean_mm", "sem_mm", "mean_px", "sem_px", "settings":
        {label: {"mean_mm", "mean_px"}}, "benchmark_s"}}, "wall_s"}``; errors in
        millimetres and pixels, over the 35 circles of each setting; times in seconds.
    """
    start = time.perf_counter()
    calibrators: dict[str, Any] = {}
    with torch_threads(1), ScratchFolder(SCRATCH_PREFIX) as folder:
        result = run_calibration(Path(folder), config, progress=False, benchmark=False)
        grid = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
        try:
            for name in CALIBRATORS:
                method = METHOD_NAMES[name]
                began = time.perf_counter()
                # One method at a time: setting k is always reset with the same seed, so each
                # method's numbers are those of the pipeline's three-method table.
                models = {method: result["models"][method]}
                rules = paper_table_rules(list(models), result["phase2"].corrected[:, 2])  # the paper's protocol, as evaluate's
                table = calibration_table(grid, models, seed=config.seed + BENCHMARK_SEED_OFFSET, progress=False, rules=rules)
                calibrators[name] = {**_errors(table_summary(table)[method]), "benchmark_s": time.perf_counter() - began}
        finally:
            grid.close()
    phase1 = result["phase1"]
    return {
        "config": {"bias_seed": config.bias_seed, "seed": config.seed},
        "phase1": {"raw": int(phase1.n_raw), "kept": int(phase1.n_kept)},
        "stages_s": dict(result["timings_s"]),
        "calibrators": calibrators,
        "wall_s": time.perf_counter() - start,
    }
