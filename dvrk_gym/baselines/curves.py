"""Learning curves against training env steps: their points, how a point is measured, and
the curves as JSON and as figures.

A point measures the deterministic policy on an evaluation env (its moves are not counted
in the training budget). GridTouch agents: the 35 circles once, the yaw cycling through
the benchmark's six settings; mean touch error (mm). Pick agents: CURVE_TRIALS debridement
trials of eight picks; success rate (and the mean true grip offset, mm, in the JSON). NaN
values (a pick agent's pixel error) are written as JSON null.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import CALIBRATOR_MOVES
from dvrk_gym.baselines.picking import GripOffsetLog
from dvrk_gym.calibration.benchmark import YAW_SETTINGS
from dvrk_gym.envs.grid_touch import N_CIRCLES, TOUR
from dvrk_gym.evaluation.episodes import run_episodes
from dvrk_gym.evaluation.trials import run_trials, totals
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_json, read_json
from dvrk_gym.utils.checks import check_float, check_int

CURVE_METRICS = ("mm_error", "success_rate")
"""What :func:`plot_curves` can draw: touch error or grip offset (mm), or success rate."""
PAPER_DNN_RF_PICK_SUCCESS = paper.DEBRIDEMENT_RESULTS[("dnn+rf", "pumpkin_seed")]["success"] / paper.DEBRIDEMENT_PICKS_PER_CELL
"""The paper's DNN+RF debridement success on pumpkin seeds (110 of 120 picks)."""

CURVE_TRIALS = 2
"""Debridement trials (of eight picks) per learning-curve point of a pick agent."""


@dataclass(frozen=True)
class CurvePoint:
    """How the deterministic policy does after ``env_steps`` training moves.

    Attributes:
        env_steps: training env steps so far.
        mm_error: GridTouch: mean touch error in the workspace plane; pick agents: mean
            true grip offset in the paper's plane from the fragment's centre; millimetres.
        pixel_error: mean touch error in the left image, pixels (NaN for pick agents).
        success_rate: fraction of touches within the env's success radius, or of picks
            that delivered their fragment.
        time_per_fragment_s: pick agents: mean simulated seconds per pick (None otherwise).
    """

    env_steps: int
    mm_error: float
    pixel_error: float
    success_rate: float
    time_per_fragment_s: float | None = None
    NAN_FIELDS: ClassVar[tuple[str, ...]] = ("mm_error", "pixel_error", "success_rate")
    """The fields that may be NaN (written as JSON null)."""

    def to_json(self) -> dict[str, Any]:
        """The point as JSON values: NaN errors (a pick agent's pixel error) as null."""
        return {key: None if isinstance(value, float) and np.isnan(value) else value for key, value in dataclasses.asdict(self).items()}

    @classmethod
    def from_json(cls, value: Any) -> CurvePoint:
        """A point from :meth:`to_json` (null errors back to NaN).

        Raises:
            TypeError: ``value`` is not a dict of this class's fields.
            ValueError: a field is not a number of its kind (a non-negative int of env
                steps; real errors and rate, null for NaN; a finite, non-negative time or null).
        """
        if not isinstance(value, dict):
            raise TypeError(f"a curve point must be a dict, got {value!r}")
        fields: dict[str, Any] = {key: float("nan") if item is None and key in cls.NAN_FIELDS else item for key, item in value.items()}
        point = cls(**fields)
        check_int("a curve point's env_steps", point.env_steps, 0)
        for name in cls.NAN_FIELDS:
            item = getattr(point, name)
            if isinstance(item, bool) or not isinstance(item, (int, float)) or math.isinf(item):
                raise ValueError(f"a curve point's {name} must be a real number or null, got {item!r}")
        if point.time_per_fragment_s is not None:
            check_float("a curve point's time_per_fragment_s", point.time_per_fragment_s, low=0.0)
        return point


def curve_options(index: int) -> dict[str, Any]:
    """Reset options of the learning curve's ``index``-th touch: the ``index``-th circle of the
    authors' tour (:data:`~dvrk_gym.envs.grid_touch.TOUR`), a cycling yaw setting."""
    return {"circle": TOUR[index % N_CIRCLES], "yaw": YAW_SETTINGS[index % len(YAW_SETTINGS)][1]}


def evaluate_curve_point(model: BaseAlgorithm, env: gym.Env, env_steps: int, seed: int) -> CurvePoint:
    """Touch the 35 circles with the deterministic policy; mean errors."""
    results = run_episodes(env, model, n_episodes=N_CIRCLES, seed=seed, options=curve_options, progress=False)
    mean = lambda key: float(np.mean([r.metrics[key] for r in results]))  # noqa: E731
    return CurvePoint(env_steps, mean("mm_error"), mean("pixel_error"), mean("is_success"))


def evaluate_pick_curve_point(model: BaseAlgorithm, env: gym.Env, env_steps: int, seed: int, *, n_trials: int = CURVE_TRIALS) -> CurvePoint:
    """Run ``n_trials`` debridement trials with the deterministic policy; success, grip offset, time."""
    log = GripOffsetLog(env)
    total = totals(run_trials(log, model, n_trials, seed=seed, progress=False))
    offsets = [mm for mm in log.offsets_mm if mm is not None]
    mean_offset = float(np.mean(offsets)) if offsets else float("nan")
    return CurvePoint(env_steps, mean_offset, float("nan"), total["success"] / max(total["picks"], 1), total["time_per_fragment_s"])


CurveEvaluator = Callable[[BaseAlgorithm, gym.Env, int, int], CurvePoint]


def save_curve(points: Sequence[CurvePoint], path: Path, meta: dict[str, Any]) -> Path:
    """Write ``{"meta": ..., "points": [{env_steps, mm_error, pixel_error, success_rate, time_per_fragment_s}]}``."""
    path = Path(path)
    return atomic_write_json(path, {"meta": meta, "points": [p.to_json() for p in points]}, indent=1)


def load_curve(path: Path) -> list[CurvePoint]:
    """Read the points written by :func:`save_curve` (null errors back to NaN).

    Raises:
        ValueError: ``path`` is not such a file (too big, not JSON, or not a list of points), naming it.
    """
    record = read_json(path)
    rows = record.get("points") if isinstance(record, dict) else None
    if not isinstance(rows, list) or not all(isinstance(row, dict) for row in rows):
        raise ValueError(f"{path} is not a learning curve: an object whose 'points' is a list of objects")
    try:
        return [CurvePoint.from_json({**dict.fromkeys(CurvePoint.NAN_FIELDS), **row}) for row in rows]  # a missing error is NaN too
    except (TypeError, ValueError) as error:
        raise ValueError(f"{path} is not a learning curve: {error}") from None


def plot_curves(
    curves: Mapping[str, Sequence[CurvePoint]],
    path: Path,
    title: str = "",
    metric: str = "mm_error",
    *,
    table_mm: Mapping[str, float] | None = None,
) -> Path:
    """One line per agent against env steps: mean touch error (mm, log scale) or success rate.

    The paper's DNN+RF result (touch error, or debridement success on pumpkin seeds) is
    drawn at the calibrator's budget of robot moves, as a reference point. ``table_mm``
    (touch error only): each agent's mean error on the calibration table (210 touches, as
    the paper's figure was measured), drawn as a hollow diamond at its curve's last step; a
    curve point touches each of the 35 circles once, so the two differ.

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
        (line,) = ax.plot([p.env_steps for p in points], [getattr(p, metric) for p in points], marker="o", markersize=3, label=label)
        if metric == "mm_error" and table_mm is not None and label in table_mm and points:
            ax.plot(
                [points[-1].env_steps],
                [table_mm[label]],
                marker="D",
                fillstyle="none",
                markersize=8,
                linestyle="none",
                color=line.get_color(),
            )
    if metric == "mm_error" and table_mm:
        ax.plot([], [], marker="D", fillstyle="none", linestyle="none", color="0.3", label="calibration table, 210 touches")
    if metric == "mm_error":
        reference, ylabel, default_title = (
            paper.CALIBRATION_MEAN_MM["DNN+RF"],
            "mean touch error, 35 circles touched once (mm)",
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
        label=f"paper DNN+RF, its table ({CALIBRATOR_MOVES:,} moves)"
        if metric == "mm_error"
        else f"paper DNN+RF ({CALIBRATOR_MOVES:,} moves)",
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
