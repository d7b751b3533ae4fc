"""The agents on the calibrators' benchmark, and one table of error against robot moves.

An agent touches the 35 circles at the six yaw settings through the same
:func:`~dvrk_gym.calibration.benchmark.touch_grid` and seeds as the calibrators in
:func:`~dvrk_gym.calibration.pipeline.run_calibration`, so their rows are comparable. The
calibrators' rows come from a calibration run folder (``calibration_table.json`` and
``pipeline_config.json``, as ``dvrk-gym evaluate`` writes them).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dvrk_gym.baselines.checkpoints import LoadedAgent
from dvrk_gym.baselines.training import make_agent_env
from dvrk_gym.calibration.benchmark import YAW_SETTINGS, CircleErrors, touch_grid
from dvrk_gym.calibration.pipeline import PipelineConfig
from dvrk_gym.envs.grid_touch import N_CIRCLES
from dvrk_gym.sim.kinematics import PAPER_YAWS_RAD

logger = logging.getLogger(__name__)

GRID_TOUCH_ID = "dvrk_gym/GridTouch-v0"
BENCHMARK_SEED = 1000
"""The seed the calibration pipeline's benchmark uses (its config seed 0 + 1000)."""
PHASE2_TOUCHES_PER_RUN = N_CIRCLES * len(PAPER_YAWS_RAD)
"""Phase II touches of a calibration run: the 35 circles at the five paper yaws."""


@dataclass(frozen=True)
class ComparisonRow:
    """One method in the comparison.

    Attributes:
        method: its name.
        robot_moves: robot moves used to build it (Phase I poses + Phase II touches, or
            training env steps).
        mm_error: mean touch error over the 35 circles x 6 settings, millimetres.
        pixel_error: the same in the left image, pixels.
        source: where the numbers come from.
    """

    method: str
    robot_moves: int
    mm_error: float
    pixel_error: float
    source: str


def benchmark_agent(agent: LoadedAgent, seed: int = BENCHMARK_SEED, progress: bool = False) -> dict[str, CircleErrors]:
    """The agent's errors at each of the six yaw settings (``table[setting]``).

    Raises:
        ValueError: the agent learnt another env than GridTouch-v0 (the grid benchmark is its).
    """
    if agent.config.spec.env_id != GRID_TOUCH_ID:
        raise ValueError(f"{agent.label} learnt {agent.config.spec.env_id}; the calibrators' benchmark needs an agent of {GRID_TOUCH_ID}")
    env = make_agent_env(agent.config, training=False)
    try:
        return {label: touch_grid(env, agent.model, yaw, seed=seed + k, progress=progress) for k, (label, yaw) in enumerate(YAW_SETTINGS)}
    finally:
        env.close()


def agent_row(agent: LoadedAgent, settings: dict[str, CircleErrors]) -> ComparisonRow:
    """The comparison row of a benchmarked agent."""
    mm = np.concatenate([e.mm for e in settings.values()])
    pixel = np.concatenate([e.pixel for e in settings.values()])
    return ComparisonRow(agent.label, agent.env_steps, float(np.mean(mm)), float(np.mean(pixel)), str(agent.path))


def calibration_rows(folder: Path) -> tuple[list[ComparisonRow], PipelineConfig]:
    """The calibrators' rows from a calibration run folder, with the run's settings.

    Robot moves: RBT and DNN use the Phase I poses (trajectories x poses per trajectory);
    DNN+RF adds the 175 Phase II touches.

    Raises:
        FileNotFoundError: the folder has no ``calibration_table.json``.
    """
    folder = Path(folder)
    table_path = folder / "calibration_table.json"
    if not table_path.exists():
        raise FileNotFoundError(f"{table_path} not found: run 'dvrk-gym evaluate --out {folder}' first")
    summary = json.loads(table_path.read_text())["summary"]
    config = _pipeline_config(folder)
    phase1 = config.n_trajectories * config.steps_per_trajectory
    moves = {"RBT": phase1, "DNN": phase1, "DNN+RF": phase1 + PHASE2_TOUCHES_PER_RUN}
    rows = []
    for method, stats in summary.items():
        every = stats["all settings"]
        rows.append(ComparisonRow(method, moves.get(method, -1), every["mm"]["mean"], every["pixel"]["mean"], str(table_path)))
    return rows, config


def _pipeline_config(folder: Path) -> PipelineConfig:
    stamp = folder / "pipeline_config.json"
    if not stamp.exists():
        logger.warning("%s not found: assuming the paper's budgets and default settings", stamp)
        return PipelineConfig()
    values: dict[str, Any] = json.loads(stamp.read_text())
    values["camera_resolution"] = tuple(values.get("camera_resolution", (1920, 1080)))
    return PipelineConfig(**values)


def setting_mismatches(agent: LoadedAgent, calibration: PipelineConfig) -> list[str]:
    """Differences between an agent's world and a calibration run's that make rows incomparable."""
    notes = []
    for name in ("bias", "bias_seed", "camera_resolution"):
        mine, theirs = getattr(agent.config, name), getattr(calibration, name)
        if mine != theirs:
            notes.append(f"{agent.label}: {name} {mine!r}, but the calibration run used {theirs!r}")
    return notes


def format_comparison(rows: list[ComparisonRow], notes: list[str] = ()) -> str:
    """Method, robot moves, mean mm and pixel error over the 35 circles x 6 settings."""
    lines = [
        "Touch error over the 35 circles x 6 yaw settings, for the robot moves each method used",
        f"{'method':<32}{'robot moves':>12}{'mean mm':>10}{'mean px':>10}",
    ]
    for row in rows:
        moves = f"{row.robot_moves:,}" if row.robot_moves >= 0 else "?"
        lines.append(f"{row.method:<32}{moves:>12}{row.mm_error:>10.2f}{row.pixel_error:>10.1f}")
    lines += [f"note: {note}" for note in notes]
    return "\n".join(lines)
