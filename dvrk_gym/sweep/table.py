"""A sweep's table: one row per cell (instrument, calibrator, seed), as CSV, text and a figure.

The columns are :data:`COLUMNS`, documented in :data:`COLUMN_DOCS`. Every number but the
wall times (``benchmark_s``, ``unit_wall_s``) is the same wherever the units ran.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.benchmark import YAW_SETTINGS
from dvrk_gym.sweep.grid import METHOD_NAMES, SweepSettings
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_text

SETTING_KEYS = {label: label.replace(" ", "") for label, _ in YAW_SETTINGS}
"""Each of the paper's six settings as a column suffix: ``yaw-90`` ... ``yaw90``, ``random``."""

COLUMN_DOCS: dict[str, str] = {
    "bias_seed": "the instrument: the seed of its cable bias draw",
    "seed": "the run seed (Phase I, the DNN, Phase II, the forests and the benchmark)",
    "calibrator": "rbt, dnn or dnn+rf",
    "mean_mm": "mean touch error over the six settings x 35 circles, mm",
    "sem_mm": "its standard error, mm",
    "mean_px": "the same in the left image, pixels",
    "sem_px": "its standard error, pixels",
    **{f"mm_{key}": f"mean touch error at {label} over the 35 circles, mm" for label, key in SETTING_KEYS.items()},
    **{f"px_{key}": f"mean touch error at {label} over the 35 circles, pixels" for label, key in SETTING_KEYS.items()},
    "phase1_raw": "Phase I samples collected",
    "phase1_kept": "Phase I samples kept (the marker seen alike by both cameras)",
    "benchmark_s": "wall time of this calibrator's 210 touches, seconds",
    "unit_wall_s": "wall time of the whole unit (the pipeline and the three benchmarks), seconds; the same in a unit's rows",
}
"""What each column of the sweep table holds."""
COLUMNS: tuple[str, ...] = tuple(COLUMN_DOCS)
"""The sweep table's columns, in order."""
TIME_COLUMNS = ("benchmark_s", "unit_wall_s")
"""The columns that depend on the machine (everything else is the same wherever a unit runs)."""


def sweep_rows(settings: SweepSettings, results: Mapping[str, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The table's rows, in the grid's order (instrument, then seed, then calibrator).

    Args:
        settings: the sweep.
        results: the finished units' results by unit name (others are left out).
    """
    rows = []
    for unit in settings.units():
        result = results.get(unit.name)
        if result is not None:
            rows.extend(unit_rows(unit.bias_seed, unit.seed, result, settings.calibrators))
    return rows


def unit_rows(bias_seed: int, seed: int, result: Mapping[str, Any], calibrators: Sequence[str]) -> list[dict[str, Any]]:
    """One unit's rows of the table, one per calibrator, every number in them checked.

    Raises:
        KeyError, TypeError: ``result`` lacks a number the table reads.
        ValueError: a number is not a finite real one (a unit file edited or damaged).
    """
    rows = []
    for name in calibrators:
        errors = result["calibrators"][name]
        per_setting = errors["settings"]
        row: dict[str, Any] = {"bias_seed": bias_seed, "seed": seed, "calibrator": name}
        row.update({key: errors[key] for key in ("mean_mm", "sem_mm", "mean_px", "sem_px")})
        row.update({f"mm_{key}": per_setting[label]["mean_mm"] for label, key in SETTING_KEYS.items()})
        row.update({f"px_{key}": per_setting[label]["mean_px"] for label, key in SETTING_KEYS.items()})
        row.update({"phase1_raw": result["phase1"]["raw"], "phase1_kept": result["phase1"]["kept"]})
        row.update({"benchmark_s": errors["benchmark_s"], "unit_wall_s": result["wall_s"]})
        for column, value in row.items():
            if column != "calibrator" and (isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value)):
                raise ValueError(f"{name}'s {column} is {value!r}, not a finite number")
        rows.append(row)
    return rows


def write_csv(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike) -> Path:
    """Write the rows as CSV with a header of :data:`COLUMNS` (floats in full precision)."""
    path = Path(path)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=COLUMNS)  # the whole table first: a bad row leaves the old file as it was
    writer.writeheader()
    writer.writerows(rows)
    return atomic_write_text(path, text.getvalue())


def format_rows(rows: Sequence[Mapping[str, Any]]) -> str:
    """The table in text: each cell's mean and per-setting errors (mm), then each calibrator
    over all instruments and seeds, beside the paper's mean."""
    keys = list(SETTING_KEYS.values())
    lines = [f"{'instrument':>10}{'seed':>6}  {'calibrator':<11}{'mean mm':>9}{'mean px':>9}" + "".join(f"{key:>9}" for key in keys)]
    for row in rows:
        settings = "".join(f"{row[f'mm_{key}']:>9.2f}" for key in keys)
        lines.append(
            f"{row['bias_seed']:>10}{row['seed']:>6}  {row['calibrator']:<11}{row['mean_mm']:>9.2f}{row['mean_px']:>9.1f}{settings}"
        )
    lines += ["", f"{'calibrator':<11}{'cells':>6}{'mean mm':>9}{'sd':>7}{'min':>7}{'max':>7}{'paper mm':>10}"]
    for name, errors in _by_calibrator(rows).items():
        reference = paper.CALIBRATION_MEAN_MM.get(METHOD_NAMES[name])
        spread = f"{np.std(errors, ddof=1):>7.2f}" if len(errors) > 1 else f"{'-':>7}"
        lines.append(
            f"{name:<11}{len(errors):>6}{np.mean(errors):>9.2f}{spread}{np.min(errors):>7.2f}{np.max(errors):>7.2f}"
            + (f"{reference:>10.2f}" if reference is not None else f"{'-':>10}")
        )
    return "\n".join(lines)


def _by_calibrator(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[float]]:
    grouped: dict[str, list[float]] = {}
    for row in rows:
        grouped.setdefault(row["calibrator"], []).append(float(row["mean_mm"]))
    return grouped


def plot_errors(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike, *, subtitle: str = "") -> Path:
    """Mean touch error per instrument, one line per calibrator, the paper's mean dashed;
    ``subtitle``, under the title: the settings every unit shared.

    With several seeds a point is the mean over them, its bar spans the lowest to the
    highest seed and each seed is a small dot.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    instruments = sorted({int(row["bias_seed"]) for row in rows})
    position = {instrument: index for index, instrument in enumerate(instruments)}
    fig, ax = plt.subplots(figsize=(max(6.0, 0.5 * len(instruments) + 4.0), 3.8))
    for name in _by_calibrator(rows):
        color = f"C{list(METHOD_NAMES).index(name)}"
        cells = [row for row in rows if row["calibrator"] == name]
        per_instrument = [[float(row["mean_mm"]) for row in cells if row["bias_seed"] == instrument] for instrument in instruments]
        xs = [position[instrument] for instrument, errors in zip(instruments, per_instrument) if errors]
        seeds = [errors for errors in per_instrument if errors]
        means = np.array([np.mean(errors) for errors in seeds])
        bars = np.array([[mean - min(errors), max(errors) - mean] for mean, errors in zip(means, seeds)]).T
        ax.errorbar(xs, means, yerr=bars, color=color, marker="o", capsize=3, label=METHOD_NAMES[name])
        if any(len(errors) > 1 for errors in seeds):
            dots = [(x, error) for x, errors in zip(xs, seeds) for error in errors]
            ax.plot(*zip(*dots), linestyle="none", marker=".", markersize=4, color=color, alpha=0.5)
        reference = paper.CALIBRATION_MEAN_MM.get(METHOD_NAMES[name])
        if reference is not None:
            ax.axhline(reference, color=color, linestyle="--", linewidth=0.8, alpha=0.7)
    ax.set_xticks(range(len(instruments)), [str(instrument) for instrument in instruments])
    ax.set_xlabel("instrument (bias seed)")
    ax.set_ylabel("mean touch error (mm)")
    ax.set_ylim(bottom=0.0)
    title = "Calibration error per instrument (6 settings x 35 circles; dashed: the paper)"
    ax.set_title(title + (f"\n{subtitle}" if subtitle else ""), fontsize=9)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    path = Path(path)
    try:
        atomic_savefig(fig, path, dpi=110)
    finally:
        plt.close(fig)
    return path
