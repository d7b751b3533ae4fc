"""Run a sweep: every unit of the grid on an executor, each result kept as it finishes.

The output folder holds ``sweep_settings.json`` (what every unit shares: the budget and
the world, and which dvrk_gym made the units; a folder made with other settings or by
another dvrk_gym is refused), ``units/<unit>.json`` (each
finished unit's numbers, written atomically as it finishes), ``sweep.csv`` (one row per
cell) and ``sweep_errors.png``. A re-run loads the finished units and runs only the rest,
so a killed sweep loses at most the units that were running; the grid may grow between
runs (more instruments, seeds or calibrators) and reuses what is there.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from dvrk_gym.calibration.pipeline import PipelineConfig
from dvrk_gym.parallel.executors import Executor
from dvrk_gym.parallel.progress_clock import running_clock
from dvrk_gym.sweep.grid import CALIBRATORS, SweepSettings, Unit
from dvrk_gym.sweep.table import plot_errors, sweep_rows, unit_rows, write_csv
from dvrk_gym.sweep.unit import run_unit
from dvrk_gym.utils.run_folder import RunFolder

logger = logging.getLogger(__name__)

SETTINGS_STAMP = "sweep_settings.json"
"""The file of a sweep folder that holds the settings every unit shares (:meth:`SweepSettings.stamp`)."""
UNITS_FOLDER = "units"
"""The subfolder of a sweep folder with each finished unit's result, ``<unit name>.json``."""
CSV_NAME = "sweep.csv"
FIGURE_NAME = "sweep_errors.png"


@dataclass(frozen=True)
class SweepResult:
    """What a sweep produced.

    Attributes:
        rows: the table, one dict per cell (:data:`~dvrk_gym.sweep.table.COLUMNS`).
        computed: the units run by this call, by name, in the order they finished.
        loaded: the units found finished in the folder.
        csv: the table's file.
        figure: the error-per-instrument figure.
        executor: where the units ran.
        wall_s: this call's wall time, seconds.
    """

    rows: list[dict[str, Any]]
    computed: tuple[str, ...]
    loaded: tuple[str, ...]
    csv: Path
    figure: Path
    executor: str
    wall_s: float


class SweepError(RuntimeError):
    """Some units failed; the message names them (the finished ones are kept and tabled)."""


def _unit_file(unit_name: str) -> str:
    """A unit's result file, relative to the sweep folder."""
    return f"{UNITS_FOLDER}/{unit_name}.json"


def _load_unit(folder: RunFolder, unit: Unit) -> dict[str, Any] | None:
    """A finished unit's result, or None when it has none (an unreadable file is moved aside by the folder)."""
    result = folder.read_json(_unit_file(unit.name))
    if result is None:
        return None
    try:
        if result["config"] != {"bias_seed": unit.bias_seed, "seed": unit.seed}:
            raise ValueError(f"it holds unit {result['config']!r}")
        unit_rows(unit.bias_seed, unit.seed, result, CALIBRATORS)  # every number the table reads, checked
    except (KeyError, TypeError, ValueError) as error:
        logger.warning(
            "%s is not this unit's whole result (%s: %s): running the unit again",
            folder.file(_unit_file(unit.name)),
            type(error).__name__,
            error,
        )
        return None
    return result


def run_sweep(settings: SweepSettings, out: str | os.PathLike, executor: Executor, *, progress: bool = True) -> SweepResult:
    """Run (or resume) a sweep in ``out``: every unit not finished there, on ``executor``.

    Args:
        settings: the grid and the budget.
        out: the output folder (created if missing).
        executor: where units run (:class:`~dvrk_gym.parallel.executors.LocalExecutor`, or
            :class:`~dvrk_gym.parallel.dask_executor.DaskExecutor` for a cluster); not closed here.
        progress: show a bar over the units.

    Raises:
        TypeError: ``settings`` is no :class:`SweepSettings`, or ``executor`` has no
            ``map_unordered`` and ``description`` (refused before ``out`` is touched).
        ValueError: ``out`` holds a sweep made with other settings or by another dvrk_gym.
        SweepError: some units failed; the others are written and tabled first, and the
            same call retries only the failed ones.
    """
    if not isinstance(settings, SweepSettings):
        raise TypeError(f"settings must be a SweepSettings (SweepSettings(bias_seeds=..., ...)), got {type(settings).__name__}")
    if not (callable(getattr(executor, "map_unordered", None)) and isinstance(getattr(executor, "description", None), str)):
        raise TypeError(
            f"executor must be an Executor (dvrk_gym.parallel.executors.local_executor(workers), or a DaskExecutor), got {executor!r}"
        )
    start = time.perf_counter()
    with RunFolder(out, settings.stamp(), stamp=SETTINGS_STAMP) as folder:
        units_dir = folder.file(UNITS_FOLDER)
        if units_dir.exists() and not units_dir.is_dir():  # mkdir would say "[Errno 17] File exists"
            raise ValueError(f"{units_dir} is not a folder, where the sweep keeps its finished units: move it away, or give another --out")
        units_dir.mkdir(exist_ok=True)
        results: dict[str, dict[str, Any]] = {}
        for unit in settings.units():
            found = _load_unit(folder, unit)
            if found is not None:
                results[unit.name] = found
        loaded = tuple(results)
        todo = [settings.unit_config(unit) for unit in settings.units() if unit.name not in results]
        logger.info("sweep in %s: %d units finished, %d to run on %s", folder.path, len(loaded), len(todo), executor.description)
        computed, failures = _run_units(todo, executor, folder, results, progress, total=len(loaded) + len(todo))
        rows = sweep_rows(settings, results)
        csv_path, figure = folder.file(CSV_NAME), folder.file(FIGURE_NAME)
        if rows:
            write_csv(rows, csv_path)
            plot_errors(rows, figure, subtitle=settings.pipeline.budget())
        else:  # every unit of this grid failed: another grid's table and figure would not be this one's,
            csv_path.unlink(missing_ok=True)  # and an empty table would be a result, keeping the folder's settings
            figure.unlink(missing_ok=True)
    if failures:
        by_message: dict[str, list[str]] = {}  # one cause (a worker of other source, say) named once, with its units
        for name, message in failures.items():
            by_message.setdefault(message, []).append(name)
        listed = "; ".join(f"{', '.join(sorted(names))} ({message})" for message, names in by_message.items())
        raise SweepError(
            f"{len(failures)} of {len(todo)} units failed: {listed}. This grid's {len(results)} finished units are in "
            f"{units_dir}{f' and tabled in {csv_path}' if rows else ''}; the same call runs only the failed ones again"
        )
    return SweepResult(rows, computed, loaded, csv_path, figure, executor.description, time.perf_counter() - start)


def _run_units(
    todo: list[PipelineConfig], executor: Executor, folder: RunFolder, results: dict[str, dict[str, Any]], progress: bool, total: int
) -> tuple[tuple[str, ...], dict[str, str]]:
    """Run the units on the executor, writing each result as it comes; returns the names
    of those computed and the failures' messages by name."""
    computed: list[str] = []
    failures: dict[str, str] = {}
    if not todo:
        return (), failures
    bar = tqdm(total=total, initial=total - len(todo), desc="sweep", unit="unit", disable=not progress)
    with bar, running_clock(bar):  # its elapsed time moves while the units (minutes each) run
        for outcome in executor.map_unordered(run_unit, todo):
            name = Unit(bias_seed=outcome.item.bias_seed, seed=outcome.item.seed).name
            if outcome.error is not None:
                failures[name] = outcome.failure
                logger.error("unit %s failed: %s", name, failures[name])
                continue
            folder.write_json(_unit_file(name), outcome.result)
            results[name] = outcome.result
            computed.append(name)
            bar.update(1)
            message = f"{name}: {outcome.result['wall_s']:.0f} s"
            bar.write(message) if progress else logger.info(message)
    return tuple(computed), failures
