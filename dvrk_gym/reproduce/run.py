"""``dvrk-gym reproduce``: the paper end to end in simulation, as one graph of cached tasks.

The run folder holds everything: ``calibration/`` (the two-phase pipeline's cached
stages), ``tasks/`` (each task's cached summary), ``debridement/``, ``baselines/``,
``figures/``, and the two outputs, ``report.md`` and ``results.json``. A re-run with the
same settings resumes from what is there; other settings are refused.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dvrk_gym.reproduce import tasks
from dvrk_gym.reproduce.profiles import QUICK, Profile
from dvrk_gym.reproduce.scheduler import Task, run_tasks

CALIBRATORS = ("dnn", "dnn+rf")
"""The calibrators of the paper's debridement table."""
FRAGMENTS = ("pumpkin_seed", "raisin")
BENCHMARK_SEED_OFFSET = 1000
"""The grid benchmark's seed is the run's seed plus this (as in the calibration pipeline)."""


@dataclass(frozen=True)
class ReproduceConfig:
    """Settings of a reproduction.

    Attributes:
        out: the run folder.
        profile: the budgets (:data:`~dvrk_gym.reproduce.profiles.QUICK` or ``FULL``).
        seed: seeds every stage.
        workers: processes running tasks side by side (results do not depend on it).
        bias: the cable bias preset.
        bias_seed: which instrument.
        progress: show progress bars.
    """

    out: Path
    profile: Profile = QUICK
    seed: int = 0
    workers: int = 1
    bias: str = "paper"
    bias_seed: int = 0
    progress: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "out", Path(self.out))
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        from dvrk_gym.sim.robot.bias import resolve_bias

        resolve_bias(self.bias)  # a clear error for an unknown preset, before any work

    def settings(self) -> dict[str, Any]:
        """What the results depend on (not ``out``, ``workers`` or ``progress``)."""
        return {"profile": self.profile.to_dict(), "seed": self.seed, "bias": self.bias, "bias_seed": self.bias_seed}


def _stamp_folder(config: ReproduceConfig) -> None:
    config.out.mkdir(parents=True, exist_ok=True)
    stamp = config.out / "reproduce_config.json"
    wanted = json.loads(json.dumps(config.settings()))
    if stamp.exists() and json.loads(stamp.read_text()) != wanted:
        raise ValueError(f"{config.out} holds a run with other settings (see {stamp}); use another --out or delete it")
    stamp.write_text(json.dumps(wanted, indent=1))


def _search_cost(model: str, search: str) -> float:
    """Rough seconds to cross-validate one model of the search (measured on 2 busy cores)."""
    from dvrk_gym.calibration.search import CHOSEN_NET, SWEEP_FOLDS

    if not model.startswith("DNN"):
        return 5.0
    if search == "quick":
        return 3.0
    units, layers = (int(part[1:]) for part in model.split("_")[1:3])
    per_fold = 5.0 if units < 300 or layers == 1 else 20.0 * (layers - 1)
    return per_fold * (10 if model == CHOSEN_NET else SWEEP_FOLDS)


def build_tasks(config: ReproduceConfig) -> list[Task]:
    """The task graph of a reproduction."""
    from dvrk_gym.baselines.budgets import resolve_budget
    from dvrk_gym.cli.debridement import cell_name

    profile, out = config.profile, config.out
    figures = out / "figures"
    calibration_folder = out / "calibration"
    resolution = profile.camera_resolution
    pipeline = {
        "n_trajectories": profile.n_trajectories, "steps_per_trajectory": profile.steps_per_trajectory,
        "dnn_epochs": profile.dnn_epochs, "bias": config.bias, "bias_seed": config.bias_seed,
        "camera_resolution": resolution, "seed": config.seed,
    }
    phase1_s = 0.9 * profile.n_trajectories * profile.steps_per_trajectory / 93
    graph = [
        Task("bias_field", tasks.bias_field, {"figure": str(figures / "bias_field.png"), "bias": config.bias, "bias_seed": config.bias_seed, "seed": config.seed}, cost_s=15),
        Task("calibration", tasks.calibration, {"folder": str(calibration_folder), "pipeline": pipeline, "progress": config.progress and config.workers == 1},
             cost_s=phase1_s + 0.03 * profile.dnn_epochs + 15),
    ]
    for model in tasks.search_models(profile.search):
        cost = _search_cost(model, profile.search)
        graph.append(Task(f"search_{model}", tasks.search_model, {"calibration_folder": str(calibration_folder), "model": model, "search": profile.search, "seed": config.seed},
                          needs=("calibration",), cost_s=cost))
    for calibrator in CALIBRATORS:
        for fragment in FRAGMENTS:
            name = cell_name(calibrator, fragment)
            graph.append(Task(name, tasks.debridement, {
                "calibration_folder": str(calibration_folder), "calibrator": calibrator, "fragment": fragment,
                "trials": profile.debridement_trials, "picks": profile.debridement_picks, "seed": config.seed,
                "resolution": resolution, "out": str(out / "debridement" / name),
            }, needs=("calibration",), cost_s=0.6 * profile.debridement_picks * profile.debridement_trials))
    steps = resolve_budget("calibrator", profile.rl_steps)
    for agent in profile.rl_agents:
        graph.append(Task(f"rl_{agent}", tasks.rl_agent, {
            "agent": agent, "steps": steps, "seed": config.seed, "eval_points": profile.rl_eval_points, "bias": config.bias,
            "bias_seed": config.bias_seed, "resolution": resolution, "benchmark_seed": config.seed + BENCHMARK_SEED_OFFSET,
            "out": str(out / "baselines" / agent),
        }, cost_s=steps / 10.0 + 10))
        for fragment in FRAGMENTS:
            name = cell_name(agent, fragment)
            graph.append(Task(name, tasks.rl_debridement, {
                "model": str(out / "baselines" / agent / "model.zip"), "fragment": fragment, "trials": profile.debridement_trials,
                "picks": profile.debridement_picks, "seed": config.seed, "bias": config.bias, "bias_seed": config.bias_seed,
                "resolution": resolution, "out": str(out / "debridement" / name),
            }, needs=(f"rl_{agent}",), cost_s=0.6 * profile.debridement_picks * profile.debridement_trials))
    return graph


@dataclass
class Reproduction:
    """What a reproduction produced.

    Attributes:
        report: path of ``report.md``.
        results: path of ``results.json``.
        data: the contents of ``results.json``.
        wall_s: wall time of this call, seconds.
    """

    report: Path
    results: Path
    data: dict[str, Any] = field(default_factory=dict)
    wall_s: float = 0.0


def run_reproduce(config: ReproduceConfig) -> Reproduction:
    """Run (or resume) a reproduction and write its report, results and figures."""
    from dvrk_gym.reproduce.report import collect_results, write_figures, write_report

    start = time.perf_counter()
    _stamp_folder(config)
    (config.out / "figures").mkdir(parents=True, exist_ok=True)
    task_results = run_tasks(build_tasks(config), config.out / "tasks", workers=config.workers, progress=config.progress)
    error_maps = Path(task_results["calibration"]["figure"])
    if error_maps.exists():
        shutil.copyfile(error_maps, config.out / "figures" / "calibration_error_maps.png")
    data = collect_results(config, task_results)
    data["figures"] = write_figures(config.out / "figures", data)
    wall = time.perf_counter() - start
    calls = _log_call(config, wall, tasks_run=sum(not result["cached"] for result in task_results.values()))
    data["calls"] = calls
    data["wall_s"] = {"this_call": wall, "all_calls": sum(call["wall_s"] for call in calls), "tasks_total": sum(r["wall_s"] for r in task_results.values())}
    results_path = config.out / "results.json"
    results_path.write_text(json.dumps(data, indent=1, default=_json_default))
    report_path = write_report(config.out / "report.md", data)
    return Reproduction(report_path, results_path, data, wall)


def _log_call(config: ReproduceConfig, wall_s: float, tasks_run: int) -> list[dict[str, Any]]:
    """Append this call to ``calls.json`` in the run folder (a resumed run has several)."""
    path = config.out / "calls.json"
    calls = json.loads(path.read_text()) if path.exists() else []
    calls.append({"wall_s": wall_s, "tasks_run": tasks_run, "workers": config.workers, "finished": time.strftime("%Y-%m-%d %H:%M:%S")})
    path.write_text(json.dumps(calls, indent=1))
    return calls


def _json_default(value: Any) -> Any:
    if dataclasses.is_dataclass(value):
        return dataclasses.asdict(value)
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)
