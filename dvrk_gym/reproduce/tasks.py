"""The tasks of a reproduction. Each is a module-level function (a worker process imports
it), seeds itself, writes its files under the run folder and returns a JSON-able summary.

All lengths in the summaries are in the units their keys name (``_mm``, ``_px``, ``_s``).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from dvrk_gym import paper
from dvrk_gym.baselines.checkpoints import load_agent, save_agent
from dvrk_gym.baselines.comparison import agent_contact, agent_row, benchmark_agent
from dvrk_gym.baselines.curves import save_curve
from dvrk_gym.baselines.resume import STATE_FILE_NAME, TrainingStateError
from dvrk_gym.baselines.training import TrainConfig, train
from dvrk_gym.baselines.transfer import pick_policy
from dvrk_gym.calibration.benchmark import table_summary
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.models.serialization import ModelFileError
from dvrk_gym.calibration.phase1 import Phase1Data
from dvrk_gym.calibration.pipeline import CALIBRATOR_FILES, PipelineConfig, run_calibration
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.calibration.search import paper_models, run_search
from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.evaluation.trials import cell_label, run_trials, save_cell, totals
from dvrk_gym.sim.robot.bias import resolve_bias
from dvrk_gym.sim.robot.bias_field import grid_rigid_means, plot_field
from dvrk_gym.sim.robot.bias_statistics import bias_statistics
from dvrk_gym.sim.robot.cables import CableModel
from dvrk_gym.sim.table.contact import DEFAULT_CONTACT
from dvrk_gym.utils.atomic import set_aside
from dvrk_gym.utils.checks import check_endoscope_resolution

logger = logging.getLogger(__name__)

MM_PER_M = 1e3


def bias_field(figure: str, *, bias: str, bias_seed: int, seed: int, samples: int = 2000) -> dict[str, Any]:
    """The cable model's error statistics and its rigid-residual field figure."""
    model = CableModel(resolve_bias(bias), bias_seed=bias_seed)
    stats = bias_statistics(model, np.random.default_rng(seed + 1), samples)
    plot_field(model, Path(figure), "rigid")
    return {
        "figure": str(figure),
        "samples": int(stats["n_samples"]),
        "raw_mean_mm": stats["raw_mean_m"] * MM_PER_M,
        "rigid_mean_mm": stats["rigid_mean_m"] * MM_PER_M,
        "rigid_by_yaw_mm": [v * MM_PER_M for v in stats["rigid_mean_by_yaw_m"]],
        "grid_rigid_by_yaw_mm": [v * MM_PER_M for v in grid_rigid_means(model)],
        "smooth_mean_mm": stats["smooth_mean_m"] * MM_PER_M,
        "hysteresis_gap_mm": stats["hysteresis_gap_m"] * MM_PER_M,
        "hysteresis_gap_min_mm": stats["hysteresis_gap_min_m"] * MM_PER_M,
    }


def calibration(folder: str, pipeline: dict[str, Any], progress: bool = False) -> dict[str, Any]:
    """The two-phase calibration and its benchmark (:func:`~dvrk_gym.calibration.pipeline.run_calibration`)."""
    result = run_calibration(Path(folder), PipelineConfig(**pipeline), progress=progress)
    phase1 = result["phase1"]
    return {
        "folder": str(folder),
        "phase1": {"raw": int(phase1.n_raw), "kept": int(phase1.n_kept)},
        "phase2_touches": int(len(result["phase2"].X)),
        "summary": result["summary"],
        "stage_s": result["timings_s"],
        "figure": str(Path(folder) / "calibration_error_maps.png"),
        **{calibration_file_key(name): str(Path(folder) / file) for name, file in CALIBRATION_FILES.items()},
    }


CALIBRATION_FILES = {"phase1": "phase1.npz", **CALIBRATOR_FILES}
"""The files of the calibration run that later tasks read (Phase I for the search, the models for the picks)."""


def calibration_file_key(name: str) -> str:
    """The key of the calibration task's result naming one of :data:`CALIBRATION_FILES`."""
    return f"{name.replace('+', '_')}_file"


def search_model(calibration_folder: str, model: str, search: str, seed: int) -> dict[str, Any]:
    """Cross-validate one model of the paper's search on the run's cleaned Phase I data."""
    quick = search == "quick"
    specs = {spec.name: spec for spec in paper_models(quick=quick)}
    if model not in specs:
        raise ValueError(f"unknown model {model!r}; the {search} search has {sorted(specs)}")
    data = Phase1Data.load(Path(calibration_folder) / "phase1.npz").cleaned()
    (result,) = run_search(data.X, data.y, models=[specs[model]], seed=seed, quick=quick, progress=False)
    return dataclasses.asdict(result)


def search_models(search: str) -> list[str]:
    """The names of the models a search of that kind scores, in the paper's order."""
    return [spec.name for spec in paper_models(quick=search == "quick")]


def debridement(
    calibration_folder: str, *, calibrator: str, fragment: str, trials: int, picks: int, seed: int, resolution: tuple[int, int], out: str
) -> dict[str, Any]:
    """One cell of the paper's debridement table: ``trials`` trials with a calibrator."""
    try:
        model, settings = load_calibrator(Path(calibration_folder), calibrator)
    except ModelFileError as error:  # the calibration task is cached while its file exists: rerunning alone fails again
        raise ModelFileError(f"{error}; delete that file and run the same command again (the calibration makes it again)") from None
    env = _debridement_env(fragment, picks, settings["bias"], int(settings["bias_seed"]), resolution, DEFAULT_CONTACT)
    method = paper.METHOD_LABELS[calibrator]
    return _debridement_cell(
        env,
        CalibratedPolicy(model, target=fragment_target),
        cell_label(calibrator, fragment),
        trials,
        seed,
        out,
        {"method": method, "calibrator": calibrator, "fragment": fragment, "contact": DEFAULT_CONTACT},
    )


def _debridement_env(fragment: str, picks: int, bias: str, bias_seed: int, resolution: Sequence[int], contact: str) -> gym.Env:
    """Debridement-v0 for one cell of the table: ``picks`` picks a trial, on the ``contact`` paper."""
    return gym.make(
        "dvrk_gym/Debridement-v0",
        fragment=fragment,
        max_picks=picks,
        bias=bias,
        bias_seed=bias_seed,
        camera_resolution=check_endoscope_resolution("resolution", resolution),
        contact=contact,
    )


def rl_debridement(
    model: str, *, fragment: str, trials: int, picks: int, seed: int, bias: str, bias_seed: int, resolution: tuple[int, int], out: str
) -> dict[str, Any]:
    """One debridement cell with a trained GridTouch agent aiming the picks
    (:func:`~dvrk_gym.baselines.transfer.pick_policy`), as the calibrators aim theirs, on the
    paper the agent learnt on (:func:`~dvrk_gym.baselines.comparison.agent_contact`)."""
    agent = load_agent(Path(model))
    contact = agent_contact(agent.config)
    env = _debridement_env(fragment, picks, bias, bias_seed, resolution, contact)
    method = f"{agent.config.agent} (RL)"
    return _debridement_cell(
        env,
        pick_policy(agent),
        cell_label(agent.label, fragment),
        trials,
        seed,
        out,
        {"method": method, "calibrator": None, "agent": agent.label, "fragment": fragment, "contact": contact},
    )


def _debridement_cell(env: Any, policy: Any, title: str, trials: int, seed: int, out: str, meta: dict[str, Any]) -> dict[str, Any]:
    """Run the trials of one cell, write its JSON and outcome grid, return its totals."""
    try:
        start = time.perf_counter()
        results = run_trials(env, policy, trials, seed=seed, progress=False)
        wall = time.perf_counter() - start
    finally:
        env.close()
    figure = save_cell(results, stem=out, meta={**meta, "seed": seed}, label=title)["png"]
    return {
        **meta,
        **totals(results),
        "trials": len(results),
        "rows": [",".join(t.outcomes) for t in results],
        "wall_s_per_trial": wall / max(len(results), 1),
        "figure": str(figure),
    }


def rl_agent(
    agent: str,
    *,
    steps: int,
    seed: int,
    eval_points: int,
    bias: str,
    bias_seed: int,
    resolution: tuple[int, int],
    benchmark_seed: int,
    out: str,
) -> dict[str, Any]:
    """Train an RL agent on GridTouch-v0 and benchmark it like the calibrators."""
    config = TrainConfig(
        agent=agent,
        steps=steps,
        seed=seed,
        bias=bias,
        bias_seed=bias_seed,
        camera_resolution=check_endoscope_resolution("resolution", resolution),
        eval_points=eval_points,
    )
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    state_path = folder / STATE_FILE_NAME  # a killed run resumes its training where the last save left it
    try:
        result = train(config, progress=False, state_path=state_path)
    except TrainingStateError as error:  # damaged, or unreadable by these libraries: as any cached result, set aside and made again
        aside = set_aside(state_path)
        logger.warning("%s; moved it to %s and trained %s from the start", error, aside, agent)
        result = train(config, progress=False, state_path=state_path)
    path = save_agent(result, folder / "model.zip")
    save_curve(result.curve, folder / "learning_curve.json", {"agent": agent, "steps_per_second": result.steps_per_second})
    loaded = load_agent(path)
    settings = benchmark_agent(loaded, seed=benchmark_seed)
    row = agent_row(loaded, settings)
    state_path.unlink(missing_ok=True)  # the task's result is complete; killed before this, it resumes from the last save
    return {
        "agent": agent,
        "label": loaded.label,
        "model": str(path),
        "env_steps": int(result.env_steps),
        "steps_per_second": float(result.steps_per_second),
        "train_s": float(result.train_seconds),
        "curve": [point.to_json() for point in result.curve],  # NaN as null: results.json stays strict JSON
        "mean_mm": row.mm_error,
        "mean_px": row.pixel_error,
        "summary": table_summary({agent: settings})[agent],
    }
