"""The paper's calibration benchmark: RBT, DNN and DNN+RF touching the 35 circles.

Table "Calibration Error Results" of the paper: for each method and six yaw settings (the
five yaws, and a random yaw per circle), the error between where the closed jaws touched
and the circle's centre, over the 35 circles, in pixels (left image) and millimetres.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.policy import CalibratedPolicy, Calibrator
from dvrk_gym.envs.grid_touch import N_CIRCLES, TOUR
from dvrk_gym.evaluation.episodes import EpisodeResult, run_episodes, summarize
from dvrk_gym.evaluation.table_protocol import RAW, HeightRule, RuledPolicy, check_rules, paper_rules
from dvrk_gym.sim.endoscope.noise import PAPER_WIDTH_PX
from dvrk_gym.sim.physics.scene import GRID_COLUMNS, GRID_ROWS
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_json
from dvrk_gym.utils.checks import check_int
from dvrk_gym.utils.source_fingerprint import source_fingerprint

logger = logging.getLogger(__name__)

YAW_SETTINGS: tuple[tuple[str, float | str], ...] = (
    ("yaw -90", -np.pi / 2),
    ("yaw -45", -np.pi / 4),
    ("yaw 0", 0.0),
    ("yaw 45", np.pi / 4),
    ("yaw 90", np.pi / 2),
    ("random", "random"),
)
"""The paper's six settings: (label, GridTouch ``yaw`` option).

The labels are the columns of the paper's table (:data:`dvrk_gym.paper.CALIBRATION_SETTINGS`)."""


@dataclass(frozen=True)
class CircleErrors:
    """Errors of one method in one setting, per circle (row-major grid order).

    Attributes:
        pixel: (35,) distance in the left image, pixels.
        mm: (35,) distance in the workspace plane, millimetres.
        yaw: (35,) the yaw asked for at each circle, radians.
        width_px: the width of the left image the pixel errors were measured in, pixels
            (the env's ``camera_resolution``; the paper's: 1920).
    """

    pixel: np.ndarray
    mm: np.ndarray
    yaw: np.ndarray
    width_px: int = PAPER_WIDTH_PX

    def __post_init__(self) -> None:
        object.__setattr__(self, "width_px", check_int("CircleErrors.width_px", self.width_px, 1))


def touch_grid_episodes(
    env: gym.Env, policy: Any, yaw: float | str, seed: int = 0, *, progress: bool = False, order: Sequence[int] = TOUR
) -> list[EpisodeResult]:
    """Touch all 35 circles once with ``policy`` at one yaw setting: the 35 episodes, each with
    its final info (GridTouch-v0's: the true tip and circle positions, m, and the errors).

    The pass starts at home with the cables relaxed (its first touch is a seeded reset with
    ``relax``), so a cell of the table does not depend on which passes ran before it in the
    same env; from one touch to the next the arm lifts and goes on, its cables keeping their
    history (hysteresis), as on the real robot. It tours the circles in ``order`` (circle
    indices, each once; default the authors' order, :data:`~dvrk_gym.envs.grid_touch.TOUR`),
    and the episodes come in that order.
    """
    if sorted(order) != list(range(N_CIRCLES)):
        raise ValueError(f"order must hold each circle index 0-{N_CIRCLES - 1} once, got {list(order)}")
    return run_episodes(
        env,
        policy,
        n_episodes=N_CIRCLES,
        seed=seed,
        options=lambda i: {"yaw": yaw, "circle": int(order[i]), "relax": i == 0},
        progress=progress,
        description=f"touch grid ({yaw if isinstance(yaw, str) else f'yaw {math.degrees(yaw):+.0f} deg'})",
    )


def touch_grid(env: gym.Env, policy: Any, yaw: float | str, seed: int = 0, *, progress: bool = False) -> CircleErrors:
    """The errors of :func:`touch_grid_episodes` (the same pass), per circle in row-major order."""
    toured = touch_grid_episodes(env, policy, yaw, seed=seed, progress=progress)
    results = [toured[i] for i in np.argsort(TOUR)]  # episode i touched circle TOUR[i]
    pick = lambda key: np.array([r.metrics.get(key, np.nan) for r in results])  # noqa: E731
    width_px = int(env.unwrapped.config.camera_resolution[0])  # type: ignore[attr-defined]
    return CircleErrors(pixel=pick("pixel_error"), mm=pick("mm_error"), yaw=pick("target_yaw"), width_px=width_px)


BENCHMARK_SEED = 1000
"""The calibration table's default seed, the same as the pipeline's and the CLI's (run seed 0 plus
1000: the benchmark's episodes never reuse the collection's seeds)."""


def calibration_table(
    env: gym.Env,
    calibrators: dict[str, Calibrator],
    seed: int = BENCHMARK_SEED,
    *,
    progress: bool = True,
    rules: Mapping[str, Sequence[HeightRule]] | None = None,
) -> dict[str, dict[str, CircleErrors]]:
    """Every method in every setting: ``table[method][setting]``.

    Setting k (of YAW_SETTINGS) is reset with seed ``seed + k``, so any method meets the same
    episodes. ``rules`` gives, for the methods it names, the height rule of each setting
    (:mod:`dvrk_gym.evaluation.table_protocol`; the paper's: :func:`paper_table_rules`); the
    other methods' predictions are sent as they are. ``progress`` shows a bar per method and
    setting.
    """
    rules = {} if rules is None else rules
    for method, method_rules in rules.items():
        if method not in calibrators:
            raise ValueError(f"rules name {method!r}, which is not among the calibrators {sorted(calibrators)}")
        check_rules(method_rules, len(YAW_SETTINGS))
    table: dict[str, dict[str, CircleErrors]] = {}
    for method, calibrator in calibrators.items():
        policy = CalibratedPolicy(calibrator)
        method_rules = rules.get(method, (RAW,) * len(YAW_SETTINGS))
        table[method] = {
            label: touch_grid(
                env, policy if method_rules[k] == RAW else RuledPolicy(policy, method_rules[k]), yaw, seed=seed + k, progress=progress
            )
            for k, (label, yaw) in enumerate(YAW_SETTINGS)
        }
        mean_mm = np.nanmean([e.mm.mean() for e in table[method].values()])
        logger.info("%s: mean touch error %.2f mm", method, mean_mm)
    return table


def paper_table_rules(methods: Sequence[str], pushed_heights_m: np.ndarray) -> dict[str, tuple[HeightRule, ...]]:
    """The authors' height rules (:func:`~dvrk_gym.evaluation.table_protocol.paper_rules`) for
    those of ``methods`` that are the paper's ("RBT", "DNN", "DNN+RF"), the band carried over
    by the reported heights ``pushed_heights_m`` (n,) m of a Phase II's pushed jaws."""
    return {method: paper_rules(method, pushed_heights_m) for method in methods if method in paper.TABLE_LIFT_MM}


def table_summary(table: dict[str, dict[str, CircleErrors]]) -> dict[str, Any]:
    """Statistics per method and setting (and over all settings), as plain numbers."""
    summary: dict[str, Any] = {}
    for method, settings in table.items():
        rows = {label: {"pixel": summarize(e.pixel), "mm": summarize(e.mm)} for label, e in settings.items()}
        every = [e for e in settings.values()]
        rows["all settings"] = {
            "pixel": summarize(np.concatenate([e.pixel for e in every])),
            "mm": summarize(np.concatenate([e.mm for e in every])),
        }
        summary[method] = rows
    return summary


def _cell(stats: dict[str, float]) -> str:
    """One setting's statistics: ``mean +- s.e. median/min/max``."""
    return f"{stats['mean']:>9.2f} +- {stats['sem']:<4.2f} {stats['median']:>4.1f}/{stats['min']:.1f}/{stats['max']:.1f}"


def format_table(table: dict[str, dict[str, CircleErrors]]) -> str:
    """The paper's table in text: mean +- s.e., median, min, max per setting; paper beside.

    The pixel errors are of the left image the touches were judged in
    (:attr:`CircleErrors.width_px` wide); the paper's (of 1920 x 1080) are scaled to that
    width beside them, and left out, with a note, when the rows come from images of several
    widths.
    """
    widths = {errors.width_px for settings in table.values() for errors in settings.values()} or {PAPER_WIDTH_PX}
    width_px = widths.pop() if len(widths) == 1 else None  # an empty table has no rows to note
    summary = table_summary(table)
    width = max([8, *(len(method) + 2 for method in summary)])  # any method name lines up
    lines = []
    for unit, key in (("pixels", "pixel"), ("mm", "mm")):
        lines.append(f"Calibration error ({unit}), over the 35 circles: mean +- s.e. / median / min / max")
        if key == "pixel" and width_px != PAPER_WIDTH_PX:
            lines.append(
                "(pixels of images of several widths: the paper's, of 1920 x 1080, are not shown)"
                if width_px is None
                else f"(pixels of a {width_px}-px-wide image; the paper's, of 1920 x 1080, scaled to it)"
            )
        cells = {method: [_cell(rows[label][key]).strip() for label, _ in YAW_SETTINGS] for method, rows in summary.items()}
        column = max([12, *(len(cell) + 2 for row in cells.values() for cell in row)])  # the widest cell lines up too
        lines.append(f"{'method':<{width}}" + "".join(label.rjust(column) for label, _ in YAW_SETTINGS))
        for method, row in cells.items():
            lines.append(f"{method:<{width}}" + "".join(cell.rjust(column) for cell in row))
            if key == "pixel" and method in paper.CALIBRATION_PIXELS and width_px is not None:
                scale = width_px / PAPER_WIDTH_PX
                lines.append(f"{'  paper':<{width}}" + "".join(f"{v * scale:.1f}".rjust(column) for v in paper.CALIBRATION_PIXELS[method]))
        lines.append("")
    lines.append(f"{'method':<{width}}{'sim mean mm':>14}{'paper mm':>10}{'difference':>12}")
    for method, rows in summary.items():
        sim = rows["all settings"]["mm"]["mean"]
        reference = paper.CALIBRATION_MEAN_MM.get(method)
        paper_cell = f"{reference:>10.2f}" if reference else f"{'-':>10}"
        diff = f"{100 * (sim - reference) / reference:+.0f}%" if reference else "-"
        lines.append(f"{method:<{width}}{sim:>14.2f}{paper_cell}{diff:>12}")
    return "\n".join(lines)


def plot_error_maps(table: dict[str, dict[str, CircleErrors]], path: Path, *, subtitle: str = "") -> Path:
    """Per-circle error maps: one row per method, one column per setting (mm, shared scale);
    ``subtitle``, under the title: the settings that made them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(table)
    vmax = max(float(np.nanmax(e.mm)) for settings in table.values() for e in settings.values())
    fig, axes = plt.subplots(len(methods), len(YAW_SETTINGS), figsize=(2.6 * len(YAW_SETTINGS), 2.3 * len(methods)), squeeze=False)
    for row, method in enumerate(methods):
        for col, (label, _) in enumerate(YAW_SETTINGS):
            errors = table[method][label].mm.reshape(GRID_ROWS, GRID_COLUMNS)
            ax = axes[row, col]
            image = ax.imshow(errors, origin="lower", cmap="magma", vmin=0.0, vmax=vmax)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{method}, {label}\nmean {np.nanmean(errors):.2f} mm", fontsize=8)
    fig.colorbar(image, ax=axes, shrink=0.8, label="touch error (mm)")
    fig.suptitle("Per-circle calibration error (grid as printed: x right, y up)" + (f"\n{subtitle}" if subtitle else ""), fontsize=10)
    try:
        return atomic_savefig(fig, path, dpi=110)
    finally:
        plt.close(fig)


def save_table(table: dict[str, dict[str, CircleErrors]], path: Path, protocol: str | None = None, notes: Sequence[str] = ()) -> Path:
    """Write the summary and the per-circle errors as JSON, with the ``protocol`` the
    predictions were sent by (:data:`~dvrk_gym.evaluation.table_protocol.PROTOCOLS`), if given,
    and ``notes`` (lines on how the rows were made, such as an agent's env changes)."""
    data = {
        "protocol": protocol,
        "notes": list(notes),
        "source": source_fingerprint().to_json(),  # which dvrk_gym made it
        "summary": table_summary(table),
        "per_circle": {
            method: {
                label: {"pixel": e.pixel.tolist(), "mm": e.mm.tolist(), "yaw": e.yaw.tolist(), "width_px": e.width_px}
                for label, e in settings.items()
            }
            for method, settings in table.items()
        },
        "paper": {
            "mean_mm": paper.CALIBRATION_MEAN_MM,
            "pixels": paper.CALIBRATION_PIXELS,
            "pixels_image_px": paper.ENDOSCOPE_RESOLUTION_PX,
        },
    }
    return atomic_write_json(path, data, indent=1)
