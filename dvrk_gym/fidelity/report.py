"""The fidelity report: the side-by-side table, ``fidelity.json`` and ``fidelity.png``.

Files are written atomically (:mod:`dvrk_gym.utils.atomic`): a reader sees the old file or
the new one, never half of one.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from dvrk_gym.fidelity.comparison import (
    CORRELATION_TOLERANCE,
    PITCH_MEDIAN_TOLERANCE_DEG,
    RELATIVE_TOLERANCE,
    SHARE_TOLERANCE,
    ComparisonRow,
    FidelityRun,
)
from dvrk_gym.fidelity.statistics import PAPER_YAWS_DEG, finite_or_none, rigid_residuals_camera
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_text
from dvrk_gym.utils.source_fingerprint import source_fingerprint

__all__ = ["JSON_NAME", "PNG_NAME", "format_table", "plot_fidelity", "report_dict", "write_report"]

JSON_NAME = "fidelity.json"
PNG_NAME = "fidelity.png"
_M_TO_MM = 1e3
_COLOURS = {"real": "tab:blue", "sim": "tab:orange"}
_BINS = 40


def _difference(row: ComparisonRow) -> str:
    if row.share:
        return f"diff {row.difference:+.3f}" if row.tolerance < 1.0 else f"diff {row.difference:+.1f}"
    return f"ratio {row.difference:.2f}"


def _sd(value: float | None) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.3g}"


def _instrument(settings: dict) -> str:
    """The settings a run may change beside the instrument's draw: the settle lag and the image size."""
    width, height = settings["camera_resolution"]
    return f"wrist settle lag {settings['wrist_settle_lag']:g}, {width} x {height} px"


def format_table(run: FidelityRun) -> str:
    """The statistics side by side: statistic, real and sim with their standard errors, ratio
    or difference, the difference in standard errors (z), target, verdict."""
    settings = run.settings
    header = (
        f"Fidelity: the authors' {run.real.rows} real Phase I rows against a simulated Phase I "
        f"(bias {settings['bias']}, bias_seed {settings['bias_seed']}, {_instrument(settings)}, {settings['trajectories']} trajectories, "
        f"seed {settings['seed']}, {run.sim_raw_rows} raw rows, {run.sim.rows} kept)"
    )
    width = max(len(row.name) for row in run.rows)
    columns = f"{'real':>8}  {'sd':>7}  {'sim':>8}  {'sd':>7}  {'sim vs real':>12}  {'z':>6}"
    lines = [header, f"{'statistic':<{width}}  {columns}  {'target':>15}  verdict"]
    for row in run.rows:
        z = "-" if row.z is None else f"{row.z:+.1f}"
        lines.append(
            f"{row.name:<{width}}  {row.real:>8.2f}  {_sd(row.real_sd):>7}  {row.sim:>8.2f}  {_sd(row.sim_sd):>7}  "
            f"{_difference(row):>12}  {z:>6}  {row.target:>15}  {'pass' if row.passed else 'FAIL'}"
        )
    lines.append(
        f"{run.passed} of {len(run.rows)} statistics within target "
        f"(ratio within {RELATIVE_TOLERANCE:.0%}, shares within {SHARE_TOLERANCE:.2f} absolute, "
        f"the pitch autocorrelation within {CORRELATION_TOLERANCE:.1f}, median pitches within {PITCH_MEDIAN_TOLERANCE_DEG:.0f} degrees)"
    )
    replicates, blocks = settings.get("bootstrap_replicates", 0), settings.get("bootstrap_block_rows")
    if replicates and isinstance(blocks, dict):
        sizes = f"{blocks['real']} rows" + ("" if blocks["sim"] == blocks["real"] else f" real, {blocks['sim']} simulated")
        lines.append(
            f"sd: standard error from a moving-block bootstrap of each side's rows ({replicates} replicates, blocks of "
            f"{sizes}; none for the kept share and the CVs); z: (sim - real) over both sds combined"
        )
    return "\n".join(lines)


def report_dict(run: FidelityRun) -> dict[str, Any]:
    """The report as JSON-ready data: settings, both statistics, the comparison rows."""
    return {
        "settings": run.settings,
        "source": source_fingerprint().to_json(),  # which dvrk_gym made it
        "targets": {
            "relative_tolerance": RELATIVE_TOLERANCE,
            "share_tolerance": SHARE_TOLERANCE,
            "pitch_median_tolerance_deg": PITCH_MEDIAN_TOLERANCE_DEG,
            "correlation_tolerance": CORRELATION_TOLERANCE,
        },
        "real": run.real.to_dict(),
        "sim": {**run.sim.to_dict(), "raw_rows": run.sim_raw_rows},
        "comparison": [
            {
                "statistic": row.name,
                "real": finite_or_none(row.real),
                "sim": finite_or_none(row.sim),
                "measure": "difference" if row.share else "ratio",
                "value": finite_or_none(row.difference),
                "tolerance": row.tolerance,
                "passed": row.passed,
                "real_sd": None if row.real_sd is None else finite_or_none(row.real_sd),
                "sim_sd": None if row.sim_sd is None else finite_or_none(row.sim_sd),
                "z": row.z,
            }
            for row in run.rows
        ],
        "passed": run.passed,
        "statistics": len(run.rows),
    }


def _angle_from_view_axis_deg(residual: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(residual, axis=1)
    cosine = np.abs(residual[:, 2]) / np.where(norm > 0, norm, 1.0)
    return np.rad2deg(np.arccos(np.clip(cosine, 0.0, 1.0)))


def _histograms(axes: Any, real: np.ndarray, sim: np.ndarray, title: str, xlabel: str) -> None:
    edges = np.histogram_bin_edges(np.concatenate([real, sim]), bins=_BINS)
    for (label, values), style in zip((("real", real), ("sim", sim)), ("-", "--")):  # dashed: told apart in greyscale too
        axes.hist(
            values,
            bins=edges,
            density=True,
            histtype="step",
            linewidth=1.5,
            linestyle=style,
            color=_COLOURS[label],
            label=f"{label} ({len(values)})",
        )
    axes.set_title(title, fontsize=9)
    axes.set_xlabel(xlabel)
    axes.set_ylabel(f"density (per {xlabel.split(' (')[0]})", fontsize=8)  # the unit, without a note on it
    axes.legend(fontsize=7)


def plot_fidelity(run: FidelityRun, path: str | os.PathLike) -> Path:
    """Save the figure: residual histograms per camera axis, the residual's angle from the
    view axis, the kept rows' pitch and yaw, and each residual in the x-z plane; real against sim."""
    residuals = {"real": rigid_residuals_camera(run.real_X, run.real_y), "sim": rigid_residuals_camera(run.sim_X, run.sim_y)}
    figure = Figure(figsize=(13, 7.5), layout="constrained")
    grid = figure.subplots(2, 4)
    for column, axis in enumerate("xyz"):
        where = "view axis" if axis == "z" else "image plane"
        _histograms(grid[0, column], residuals["real"][:, column] * _M_TO_MM, residuals["sim"][:, column] * _M_TO_MM,
                    f"rigid residual along camera {axis} ({where})", "mm")  # fmt: skip
    _histograms(grid[0, 3], _angle_from_view_axis_deg(residuals["real"]), _angle_from_view_axis_deg(residuals["sim"]),
                "residual direction: angle from the view axis", "deg (0: along the view axis)")  # fmt: skip
    _histograms(grid[1, 0], np.rad2deg(run.real_X[:, 4]), np.rad2deg(run.sim_X[:, 4]), "pitch of kept rows", "deg")
    _histograms(grid[1, 1], np.rad2deg(run.real_X[:, 3]), np.rad2deg(run.sim_X[:, 3]), "yaw of kept rows", "deg")
    for yaw in PAPER_YAWS_DEG:
        grid[1, 1].axvline(yaw, color="0.7", linewidth=0.5)
    reach_mm = max(np.abs(residual[:, [0, 2]]).max() for residual in residuals.values()) * _M_TO_MM * 1.05
    for column, label in ((2, "real"), (3, "sim")):
        axes = grid[1, column]
        axes.scatter(residuals[label][:, 0] * _M_TO_MM, residuals[label][:, 2] * _M_TO_MM, s=2, alpha=0.4, color=_COLOURS[label])
        axes.set_title(f"{label}: residual directions, camera x-z", fontsize=9)
        axes.set(xlabel="camera x (mm)", ylabel="camera z, view axis (mm)", xlim=(-reach_mm, reach_mm), ylim=(-reach_mm, reach_mm))
        axes.set_aspect("equal", adjustable="box")
    settings = run.settings
    figure.suptitle(
        f"Real Phase I rows against simulation (bias {settings['bias']}, bias_seed {settings['bias_seed']}, "
        f"{_instrument(settings)}, {settings['trajectories']} trajectories): {run.passed} of {len(run.rows)} statistics within target",
        fontsize=10,
    )
    return atomic_savefig(figure, path, dpi=120, format="png")


def write_report(run: FidelityRun, out: str | os.PathLike) -> tuple[Path, Path]:
    """Write ``fidelity.json`` and ``fidelity.png`` into ``out`` (created if missing), atomically.

    Returns:
        The paths of the JSON file and the figure.
    """
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    figure_path = plot_fidelity(run, folder / PNG_NAME)  # first: a figure that fails leaves the last run's pair
    return atomic_write_text(folder / JSON_NAME, json.dumps(report_dict(run), indent=1)), figure_path
