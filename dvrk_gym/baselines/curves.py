"""Learning curves: touch error against training env steps, as JSON and as a figure."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, Sequence

from dvrk_gym.baselines.budgets import CALIBRATOR_MOVES
from dvrk_gym.baselines.training import CurvePoint
from dvrk_gym.calibration.benchmark import PAPER_MEAN_MM


def save_curve(points: Sequence[CurvePoint], path: Path, meta: dict[str, Any]) -> Path:
    """Write ``{"meta": ..., "points": [{env_steps, mm_error, pixel_error, success_rate}]}``."""
    path = Path(path)
    path.write_text(json.dumps({"meta": meta, "points": [dataclasses.asdict(p) for p in points]}, indent=1))
    return path


def load_curve(path: Path) -> list[CurvePoint]:
    """Read the points written by :func:`save_curve`."""
    return [CurvePoint(**point) for point in json.loads(Path(path).read_text())["points"]]


def plot_curves(curves: dict[str, Sequence[CurvePoint]], path: Path, title: str = "") -> Path:
    """Mean touch error (mm, log scale) against env steps, one line per agent.

    The paper's DNN+RF error is drawn at the calibrator's budget of robot moves, as a
    reference point.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for label, points in curves.items():
        ax.plot([p.env_steps for p in points], [p.mm_error for p in points], marker="o", markersize=3, label=label)
    ax.plot([CALIBRATOR_MOVES], [PAPER_MEAN_MM["DNN+RF"]], marker="*", markersize=12, linestyle="none", color="k", label="paper DNN+RF (5,476 moves)")
    ax.axvline(CALIBRATOR_MOVES, color="0.7", linestyle=":", linewidth=1)
    ax.set_yscale("log")
    ax.set_xlabel("training env steps (robot moves)")
    ax.set_ylabel("mean touch error over 35 circles (mm)")
    ax.set_title(title or "Learning curve on GridTouch-v0", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
