"""``dvrk-gym reproduce``: the paper end to end in simulation, as one graph of cached tasks.

The run folder holds everything: ``calibration/`` (the two-phase pipeline's cached
stages), ``tasks/`` (each task's cached summary), ``debridement/``, ``baselines/``,
``figures/``, and the two outputs, ``report.md`` and ``results.json``. A re-run with the
same settings resumes from what is there; other settings are refused. The tasks run on an
executor (:mod:`dvrk_gym.parallel`): this process, local processes, or a Dask cluster,
with the same results.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import resolve_budget
from dvrk_gym.calibration.pipeline import BENCHMARK_SEED_OFFSET
from dvrk_gym.calibration.search import CHOSEN_NET, SWEEP_FOLDS
from dvrk_gym.evaluation.trials import cell_name
from dvrk_gym.parallel.executors import MAX_LOCAL_WORKERS, Executor, InlineExecutor, local_executor
from dvrk_gym.parallel.task_graph import Task, run_tasks
from dvrk_gym.reproduce import tasks
from dvrk_gym.reproduce.profiles import QUICK, Profile
from dvrk_gym.reproduce.report import collect_results, relative_to_run, render_report, write_figures
from dvrk_gym.sim.robot.bias import resolve_bias
from dvrk_gym.utils.atomic import atomic_write_bytes, atomic_write_text, read_bounded, read_json
from dvrk_gym.utils.checks import check_bool, check_int
from dvrk_gym.utils.run_folder import RunFolder

CALIBRATORS = tuple(dict.fromkeys(method for method, _ in paper.DEBRIDEMENT_RESULTS))
"""The calibrators of the paper's debridement table: "dnn", "dnn+rf"."""
FRAGMENTS = tuple(paper.FRAGMENT_LABELS)
"""The fragments of the paper's debridement table: "pumpkin_seed", "raisin"."""
SETTINGS_STAMP = "reproduce_config.json"
"""The file of a run folder that holds its settings (:meth:`ReproduceConfig.settings`)."""


@dataclass(frozen=True)
class ReproduceConfig:
    """Settings of a reproduction.

    Attributes:
        out: the run folder.
        profile: the budgets (:data:`~dvrk_gym.reproduce.profiles.QUICK` or ``FULL``).
        seed: seeds every stage.
        workers: processes running tasks side by side when no executor is given to
            :func:`run_reproduce` (1: in this process; results do not depend on it).
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
        if not isinstance(self.profile, Profile):
            raise ValueError(f"ReproduceConfig.profile must be a Profile, got {type(self.profile).__name__}")
        check_int("ReproduceConfig.workers", self.workers, 1, MAX_LOCAL_WORKERS)
        check_int("ReproduceConfig.seed", self.seed, 0, 2**31 - 1)
        check_int("ReproduceConfig.bias_seed", self.bias_seed, 0, 2**31 - 1)
        check_bool("ReproduceConfig.progress", self.progress)
        if not isinstance(self.bias, str):
            raise ValueError(f"ReproduceConfig.bias must be a preset name (str), got {self.bias!r}")
        resolve_bias(self.bias)  # a clear error for an unknown preset, before any work

    def settings(self) -> dict[str, Any]:
        """What the results depend on (not ``out``, ``workers`` or ``progress``)."""
        return {"profile": self.profile.to_dict(), "seed": self.seed, "bias": self.bias, "bias_seed": self.bias_seed}


def _search_cost(model: str, search: str) -> float:
    """Rough seconds to cross-validate one model of the search (measured on 2 busy cores)."""
    if not model.startswith("DNN"):
        return 5.0
    if search == "quick":
        return 3.0
    units, layers = (int(part[1:]) for part in model.split("_")[1:3])
    per_fold = 5.0 if units < 300 or layers == 1 else 20.0 * (layers - 1)
    return per_fold * (paper.SEARCH_FOLDS if model == CHOSEN_NET else SWEEP_FOLDS)


def _debridement_task(
    config: ReproduceConfig, name: str, function: Callable[..., dict[str, Any]], kwargs: dict[str, Any], need: str
) -> Task:
    """One cell of the debridement table: ``function(**kwargs)`` with the profile's trials, picks and camera."""
    profile = config.profile
    cell = {
        "trials": profile.debridement_trials,
        "picks": profile.debridement_picks,
        "seed": config.seed,
        "resolution": profile.camera_resolution,
        "out": str(config.out / "debridement" / name),
    }
    cost_s = 0.6 * profile.debridement_picks * profile.debridement_trials
    return Task(name, function, {**kwargs, **cell}, needs=(need,), cost_s=cost_s, files=("figure",))


def _calibration_tasks(config: ReproduceConfig, nested_progress: bool) -> list[Task]:
    """The cable model's statistics, the two-phase calibration (with its own progress bars if
    ``nested_progress``), the model search and the calibrators' debridement cells."""
    profile, calibration_folder = config.profile, str(config.out / "calibration")
    pipeline = {
        "n_trajectories": profile.n_trajectories,
        "steps_per_trajectory": profile.steps_per_trajectory,
        "dnn_epochs": profile.dnn_epochs,
        "bias": config.bias,
        "bias_seed": config.bias_seed,
        "camera_resolution": profile.camera_resolution,
        "seed": config.seed,
    }
    phase1_s = 0.9 * profile.n_trajectories * profile.steps_per_trajectory / paper.PHASE1_POSES_PER_TRAJECTORY
    world = {"bias": config.bias, "bias_seed": config.bias_seed, "seed": config.seed}
    graph = [
        Task(
            "bias_field",
            tasks.bias_field,
            {"figure": str(config.out / "figures" / "bias_field.png"), **world},
            cost_s=3,
            files=("figure",),
        ),
        Task(
            "calibration",
            tasks.calibration,
            {"folder": calibration_folder, "pipeline": pipeline, "progress": config.progress and nested_progress},
            cost_s=phase1_s + 0.03 * profile.dnn_epochs + 15,
            # a model gone runs it again (its cached stages make the rest), never the picks' load with default settings
            files=tuple(tasks.calibration_file_key(name) for name in tasks.CALIBRATION_FILES),
        ),
    ]
    for model in tasks.search_models(profile.search):
        kwargs = {"calibration_folder": calibration_folder, "model": model, "search": profile.search, "seed": config.seed}
        graph.append(
            Task(f"search_{model}", tasks.search_model, kwargs, needs=("calibration",), cost_s=_search_cost(model, profile.search))
        )
    for calibrator in CALIBRATORS:
        for fragment in FRAGMENTS:
            kwargs = {"calibration_folder": calibration_folder, "calibrator": calibrator, "fragment": fragment}
            graph.append(_debridement_task(config, cell_name(calibrator, fragment), tasks.debridement, kwargs, "calibration"))
    return graph


def _rl_tasks(config: ReproduceConfig) -> list[Task]:
    """Each RL agent's training and benchmark, and its debridement cells."""
    profile, graph = config.profile, []
    steps = resolve_budget("calibrator", profile.rl_steps)
    world = {"bias": config.bias, "bias_seed": config.bias_seed, "resolution": profile.camera_resolution}
    for agent in profile.rl_agents:
        folder = config.out / "baselines" / agent
        training = {"agent": agent, "steps": steps, "seed": config.seed, "eval_points": profile.rl_eval_points, **world}
        benchmark = {"benchmark_seed": config.seed + BENCHMARK_SEED_OFFSET, "out": str(folder)}
        graph.append(Task(f"rl_{agent}", tasks.rl_agent, {**training, **benchmark}, cost_s=steps / 10.0 + 10, files=("model",)))
        for fragment in FRAGMENTS:
            kwargs = {"model": str(folder / "model.zip"), "fragment": fragment, "bias": config.bias, "bias_seed": config.bias_seed}
            graph.append(_debridement_task(config, cell_name(agent, fragment), tasks.rl_debridement, kwargs, f"rl_{agent}"))
    return graph


def build_tasks(config: ReproduceConfig, nested_progress: bool = False) -> list[Task]:
    """The task graph of a reproduction (``nested_progress``: the tasks run in this process,
    where their own progress bars can show)."""
    return _calibration_tasks(config, nested_progress) + _rl_tasks(config)


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


def run_reproduce(config: ReproduceConfig, executor: Executor | None = None) -> Reproduction:
    """Run (or resume) a reproduction and write its report, results and figures.

    Args:
        config: the settings.
        executor: where the tasks run (not closed here), e.g. a
            :class:`~dvrk_gym.parallel.dask_executor.DaskExecutor` for a cluster, whose workers
            must see ``config.out`` at the same path; None: ``config.workers`` local ones.

    Raises:
        ValueError: ``config.out`` holds a run made with other settings or by another dvrk_gym.
        RunFolderBusy: another process is running in ``config.out``.
        TaskError: a task failed (the others are cached: the same call resumes).
    """
    with RunFolder(config.out, config.settings(), stamp=SETTINGS_STAMP) as folder, contextlib.ExitStack() as stack:
        runner = executor if executor is not None else stack.enter_context(local_executor(config.workers))
        return _reproduce(config, folder, runner)


def _reproduce(config: ReproduceConfig, folder: RunFolder, executor: Executor) -> Reproduction:
    start = time.perf_counter()
    (config.out / "figures").mkdir(parents=True, exist_ok=True)
    graph = build_tasks(config, nested_progress=isinstance(executor, InlineExecutor))
    cache_dir = config.out / "tasks"
    finished_before = _finished(graph, cache_dir)
    try:
        task_results = run_tasks(
            graph, cache_dir=cache_dir, progress=config.progress, executor=executor, shared_folder=config.out, label="reproduce"
        )
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the call's time is kept beside its finished tasks, for the report
        tasks_run = len(_finished(graph, cache_dir) - finished_before)
        wall = time.perf_counter() - start
        with contextlib.suppress(OSError, ValueError):  # a record that cannot be written (a full disk) does not hide the interrupt
            folder.write_json("calls.json", _calls_with_this_one(folder, config, executor, wall, tasks_run=tasks_run, interrupted=True))
        raise
    # Everything the outputs hold is made before any is written: a cached result that was
    # edited or damaged fails here, clearly, and leaves the outputs of the last good call.
    try:
        error_maps = config.out / relative_to_run(task_results["calibration"]["figure"], config.out)
        data = collect_results(config, task_results, executor.description)
        data["figures"] = write_figures(config.out / "figures", data)
        wall = time.perf_counter() - start
        calls = _calls_with_this_one(folder, config, executor, wall, tasks_run=sum(not r["cached"] for r in task_results.values()))
        data["calls"] = calls
        data["wall_s"] = {
            "this_call": wall,
            "all_calls": sum(call["wall_s"] for call in calls),
            "tasks_total": sum(r["wall_s"] for r in task_results.values()),
        }
        results = json.dumps(data, indent=1, default=_json_default)
        report = render_report(data)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as error:
        raise ValueError(
            f"the cached task results in {config.out / 'tasks'} do not hold what the report reads ({type(error).__name__}: {error}); "
            "one was edited or damaged: delete the files you changed there and run the same command again (only those tasks run again)"
        ) from None
    if error_maps.exists():
        atomic_write_bytes(config.out / "figures" / "calibration_error_maps.png", _read_figure(error_maps, config.out))
    folder.write_json("calls.json", calls)
    results_path = atomic_write_text(config.out / "results.json", results)
    report_path = atomic_write_text(config.out / "report.md", report)
    return Reproduction(report_path, results_path, data, wall)


MAX_FIGURE_BYTES = 64 * 2**20
"""The largest figure a cached task result may name, bytes (the error maps take about 0.3 MB)."""


def _read_figure(path: Path, run_folder: Path) -> bytes:
    """A figure a cached task result names: a regular file inside the run folder, of at most
    :data:`MAX_FIGURE_BYTES` (an edited result could name a FIFO, which blocks, or a device)."""
    try:
        if not Path(os.path.realpath(path)).is_relative_to(os.path.realpath(run_folder)):
            raise ValueError(f"{path} lies outside {run_folder}")
        return read_bounded(path, MAX_FIGURE_BYTES, "a figure")
    except ValueError as error:
        raise ValueError(
            f"the cached calibration result in {run_folder / 'tasks'} names {path} as its figure: not a file of at most "
            f"{MAX_FIGURE_BYTES:,} bytes inside the run folder ({error}); delete tasks/calibration.json and run the same command again"
        ) from None


def _read_calls(path: Path) -> list[dict[str, Any]]:
    calls = read_json(path)
    if not isinstance(calls, list) or not all(isinstance(call, dict) and isinstance(call.get("wall_s"), (int, float)) for call in calls):
        raise ValueError("not a list of calls with their wall_s")
    return calls


def _finished(graph: list[Task], cache_dir: Path) -> set[str]:
    """The graph's tasks whose results are cached in ``cache_dir`` (by task name, as :func:`run_tasks` keeps them) now."""
    return {task.name for task in graph if (cache_dir / f"{task.name}.json").is_file()}


def _calls_with_this_one(
    folder: RunFolder, config: ReproduceConfig, executor: Executor, wall_s: float, *, tasks_run: int, interrupted: bool = False
) -> list[dict[str, Any]]:
    """The calls of ``calls.json`` in the run folder (a resumed run has several) and this one,
    to be written (an interrupted one too: its time counts in the report's wall time)."""
    calls = folder.load("calls.json", _read_calls) or []
    calls.append(
        {
            "wall_s": wall_s,
            "tasks_run": tasks_run,
            "interrupted": interrupted,
            "workers": config.workers,
            "executor": executor.description,
            "finished": time.strftime("%Y-%m-%d %H:%M:%S"),
        }
    )
    return calls


CLOCK_KEYS = frozenset(
    {"wall_s", "wall_s_per_trial", "seconds", "steps_per_second", "train_s", "eval_seconds", "task_wall_s", "stage_s", "calls"}
)
"""Keys of ``results.json`` whose values are wall-clock times, or the record of the calls that made them."""
RUN_KEYS = frozenset({"task_cached", "workers", "executor"})
"""Keys of ``results.json`` that say how a run went (tasks loaded from the cache, workers, where the
tasks ran), not what it found."""


def seeded_results(value: Any) -> Any:
    """A ``results.json`` tree without its wall-clock times and run records: what the seed decides.

    Two runs with the same settings give equal trees, whether interrupted and resumed or
    run with any number of workers or on any executor.
    """
    if isinstance(value, dict):
        return {key: seeded_results(item) for key, item in value.items() if key not in CLOCK_KEYS | RUN_KEYS}
    if isinstance(value, list):
        return [seeded_results(item) for item in value]
    return value


def _json_default(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)
