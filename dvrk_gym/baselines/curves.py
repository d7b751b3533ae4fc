"""Learning curves against training env steps, as JSON and as figures.

GridTouch agents: mean touch error (mm). Pick agents: debridement success rate (and the
mean true grip offset, mm, in the JSON). NaN values (a pick agent's pixel error) are
written as JSON null.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import CALIBRATOR_MOVES
from dvrk_gym.baselines.training import CurvePoint
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_json, read_json

CURVE_METRICS = ("mm_error", "success_rate")
"""What :func:`plot_curves` can draw: touch error or grip offset (mm), or success rate."""
PAPER_DNN_RF_PICK_SUCCESS = paper.DEBRIDEMENT_RESULTS[("dnn+rf", "pumpkin_seed")]["success"] / paper.DEBRIDEMENT_PICKS_PER_CELL
"""The paper's DNN+RF debridement success on pumpkin seeds (110 of 120 picks)."""


def save_curve(points: Sequence[CurvePoint], path: Path, meta: dict[str, Any]) -> Path:
    """Write ``{"meta": ..., "points": [{env_steps, mm_error, pixel_error, success_rate, time_per_fragment_s}]}``."""
    path = Path(path)
    return atomic_write_json(path, {"meta": meta, "points": [p.to_json() for p in points]}, indent=1)


def load_curve(path: Path) -> list[CurvePoint]:
    """Read the points written by :func:`save_curve` (null errors back to NaN)."""
    rows = read_json(path)["points"]
    return [CurvePoint.from_json({**dict.fromkeys(CurvePoint.NAN_FIELDS), **row}) for row in rows]  # a missing error is NaN too


def plot_curves(curves: Mapping[str, Sequence[CurvePoint]], path: Path, title: str = "", metric: str = "mm_error") -> Path:
    """One line per agent against env steps: mean touch error (mm, log scale) or success rate.

    The paper's DNN+RF result (touch error, or debridement success on pumpkin seeds) is
    drawn at the calibrator's budget of robot moves, as a reference point.

    Raises:
        ValueError: ``metric`` is not one of :data:`CURVE_METRICS`.
    """
    if metric not in CURVE_METRICS:
        raise ValueError(f"metric must be one of {CURVE_METRICS}, got {metric!r}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for label, points in curves.items():
        ax.plot([p.env_steps for p in points], [getattr(p, metric) for p in points], marker="o", markersize=3, label=label)
    if metric == "mm_error":
        reference, ylabel, default_title = (
            paper.CALIBRATION_MEAN_MM["DNN+RF"],
            "mean touch error over 35 circles (mm)",
            "Learning curve on GridTouch-v0",
        )
        ax.set_yscale("log")
    else:
        reference, ylabel, default_title = PAPER_DNN_RF_PICK_SUCCESS, "debridement success rate", "Learning curve on Debridement-v0"
        ax.set_ylim(-0.02, 1.02)
    ax.plot(
        [CALIBRATOR_MOVES],
        [reference],
        marker="*",
        markersize=12,
        linestyle="none",
        color="k",
        label=f"paper DNN+RF ({CALIBRATOR_MOVES:,} moves)",
    )
    ax.axvline(CALIBRATOR_MOVES, color="0.7", linestyle=":", linewidth=1)
    ax.set_xlabel("training env steps (robot moves)")
    ax.set_ylabel(ylabel)
    ax.set_title(title or default_title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        return atomic_savefig(fig, path, dpi=110)
    finally:
        plt.close(fig)
