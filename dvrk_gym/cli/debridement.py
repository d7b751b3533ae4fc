"""The debridement command of ``dvrk-gym`` and the paper's trial table.

``dvrk-gym debride`` loads a calibrator from a calibration run folder (running the
two-phase pipeline there first if it holds no models), and runs the paper's debridement
trials with it: each trial is one Debridement-v0 episode of eight picks, run through
:func:`dvrk_gym.evaluation.episodes.run_episodes` with a
:class:`~dvrk_gym.calibration.policy.CalibratedPolicy` whose target is the next fragment
the endoscope sees, so any policy can be judged the same way. It prints and writes the
trial table (one row per trial: the outcome string, successes, time per fragment) with
totals, and a picture of the outcome grid.
"""

from __future__ import annotations

import argparse
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dvrk_gym.cli.options import add_instrument_options, add_progress_option

logger = logging.getLogger(__name__)

CALIBRATOR_FILES = {"rbt": "rbt.npz", "dnn": "dnn.npz", "dnn+rf": "two_phase.npz"}
CALIBRATOR_LABELS = {"rbt": "RBT", "dnn": "DNN", "dnn+rf": "DNN+RF"}
FRAGMENT_LABELS = {"pumpkin_seed": "pumpkin seeds", "raisin": "raisins"}
PAPER_RESULTS = {
    ("dnn", "pumpkin_seed"): {"success": 73, "A": 34, "B": 13, "C": 0},
    ("dnn+rf", "pumpkin_seed"): {"success": 110, "A": 1, "B": 9, "C": 0},
    ("dnn", "raisin"): {"success": 113, "A": 4, "B": 0, "C": 3},
    ("dnn+rf", "raisin"): {"success": 119, "A": 1, "B": 0, "C": 0},
}
"""The paper's debridement table: outcomes of 15 trials x 8 fragments."""
OUTCOME_COLOURS = {"-": "#4caf50", "A": "#e53935", "B": "#fb8c00", "C": "#8e24aa", "": "#bdbdbd"}


@dataclass(frozen=True)
class Trial:
    """One debridement trial.

    Attributes:
        outcomes: the outcome of each pick, in pick order ("-", "A", "B" or "C").
        time_per_fragment_s: simulated seconds per pick.
        phase_s: mean seconds of each phase (to seed ... drop and rotate).
        sim_error: what went wrong in the physics, or None.
    """

    outcomes: list[str]
    time_per_fragment_s: float
    phase_s: dict[str, float]
    sim_error: str | None = None


def cell_name(method: str, fragment: str) -> str:
    """File stem of one cell of the debridement table: ``debridement_dnn_rf_raisin``."""
    return f"debridement_{method.replace('+', '_')}_{fragment}"


def load_calibrator(folder: Path, name: str, bias: str = "paper", bias_seed: int = 0) -> tuple[Any, dict[str, Any]]:
    """A calibrator from a calibration run folder, and the run's settings.

    Runs the calibration pipeline in ``folder`` first if the model file is missing (its
    stages are cached, so an interrupted run resumes). The settings come from the
    folder's ``pipeline_config.json`` when it has one, else from ``bias``/``bias_seed``.

    Args:
        folder: a folder written by ``dvrk-gym calibrate`` or ``evaluate``.
        name: "rbt", "dnn" or "dnn+rf".
    """
    from dvrk_gym.calibration.models.dnn import DNNCalibrator
    from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
    from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
    from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator

    if name not in CALIBRATOR_FILES:
        raise ValueError(f"unknown calibrator {name!r}; expected one of {sorted(CALIBRATOR_FILES)}")
    folder = Path(folder)
    stamp = folder / "pipeline_config.json"
    settings = json.loads(stamp.read_text()) if stamp.exists() else {"bias": bias, "bias_seed": bias_seed}
    path = folder / CALIBRATOR_FILES[name]
    if not path.exists():
        logger.warning("%s has no %s: running the calibration pipeline there (cached stages)", folder, path.name)
        fields = {k: (tuple(v) if k == "camera_resolution" else v) for k, v in settings.items()}
        run_calibration(folder, PipelineConfig(**fields), benchmark=False)
        settings = json.loads(stamp.read_text())
    loader = {"rbt": RigidBodyCalibrator, "dnn": DNNCalibrator, "dnn+rf": TwoPhaseCalibrator}[name]
    return loader.load(path), settings


def run_trials(env: Any, policy: Any, n_trials: int, seed: int = 0, progress: bool = True) -> list[Trial]:
    """Run ``n_trials`` debridement episodes of ``policy`` (any policy) and collect the table.

    Args:
        env: a Debridement-v0 environment in primitive mode.
        policy: anything :func:`dvrk_gym.evaluation.episodes.run_episodes` accepts.
        n_trials: how many trials (episodes).
        seed: the first trial's reset seed; the rest continue its stream.
    """
    from dvrk_gym.envs.debridement import PHASES
    from dvrk_gym.evaluation.episodes import run_episodes

    results = run_episodes(env, policy, n_trials, seed=seed, progress=progress, description="debridement trials")
    trials = []
    for result in results:
        info = result.final_info
        outcomes = [o for o in str(info.get("outcomes", "")).split(",") if o]
        phases = {name: float(info.get(f"time_{name}_s", float("nan"))) for name in PHASES}
        trials.append(Trial(outcomes, float(info.get("time_per_fragment", float("nan"))), phases, info.get("sim_error")))
    return trials


def totals(trials: list[Trial]) -> dict[str, Any]:
    """Counts over all trials: picks, success, A, B, C; mean time per fragment and phases (s)."""
    from dvrk_gym.sim.table.judge import outcome_counts

    every = [o for t in trials for o in t.outcomes]
    counts = outcome_counts(every)
    weights = np.array([len(t.outcomes) for t in trials], dtype=float)
    timed = weights > 0
    mean = lambda values: float(np.average(np.array(values)[timed], weights=weights[timed])) if timed.any() else float("nan")  # noqa: E731
    phases = {name: mean([t.phase_s[name] for t in trials]) for name in (trials[0].phase_s if trials else {})}
    return {
        "picks": len(every),
        **counts,
        "time_per_fragment_s": mean([t.time_per_fragment_s for t in trials]),
        "phase_s": phases,
        "sim_errors": sum(t.sim_error is not None for t in trials),
    }


def format_trial_table(trials: list[Trial], calibrator: str, fragment: str, seed: int = 0) -> str:
    """The paper's trial table in text: one row per trial, totals, the paper's figures beside."""
    from dvrk_gym.envs.debridement import PAPER_PHASE_S

    label = CALIBRATOR_LABELS.get(calibrator, calibrator)
    lines = [f"Debridement of {FRAGMENT_LABELS.get(fragment, fragment)} with {label}: {len(trials)} trials (seed {seed})"]
    lines.append(f"{'trial':>5}  {'outcomes':<17}{'successes':>10}{'s/fragment':>12}")
    for i, trial in enumerate(trials, start=1):
        note = f"  sim error: {trial.sim_error}" if trial.sim_error else ""
        successes = sum(o == "-" for o in trial.outcomes)
        lines.append(f"{i:>5}  {','.join(trial.outcomes):<17}{f'{successes}/{len(trial.outcomes)}':>10}{trial.time_per_fragment_s:>12.2f}{note}")
    total = totals(trials)
    picks = max(total["picks"], 1)
    lines.append(
        f"total  success {total['success']}/{total['picks']} ({100 * total['success'] / picks:.1f}%), "
        f"A {total['A']}, B {total['B']}, C {total['C']}; {total['time_per_fragment_s']:.2f} s per fragment"
    )
    paper = PAPER_RESULTS.get((calibrator, fragment))
    if paper:
        lines.append(f"paper  success {paper['success']}/120 ({100 * paper['success'] / 120:.1f}%), A {paper['A']}, B {paper['B']}, C {paper['C']}; 7.2-7.3 s per fragment")
    phases = ", ".join(f"{name.replace('_', ' ')} {total['phase_s'][name]:.2f} ({PAPER_PHASE_S[name]:.2f})" for name in total["phase_s"])
    lines.append(f"phases, s (paper): {phases}")
    if total["sim_errors"]:
        lines.append(f"{total['sim_errors']} trial(s) ended with a physics failure")
    return "\n".join(lines)


def save_trials(trials: list[Trial], path: Path, meta: dict[str, Any]) -> Path:
    """Write the trials, totals and the run's settings as JSON."""
    data = {
        **meta,
        "trials": [{"outcomes": ",".join(t.outcomes), "time_per_fragment_s": t.time_per_fragment_s, "phase_s": t.phase_s, "sim_error": t.sim_error} for t in trials],
        "totals": totals(trials),
        "paper": PAPER_RESULTS.get((meta.get("calibrator"), meta.get("fragment"))),
    }
    path = Path(path)
    path.write_text(json.dumps(data, indent=1))
    return path


def plot_outcome_grid(trials: list[Trial], path: Path, title: str) -> Path:
    """A trials x picks grid, each cell coloured (and lettered) by its outcome."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    keys = list(OUTCOME_COLOURS)
    width = max([len(t.outcomes) for t in trials] + [8])
    grid = np.full((len(trials), width), keys.index(""))
    for row, trial in enumerate(trials):
        for col, outcome in enumerate(trial.outcomes):
            grid[row, col] = keys.index(outcome)
    fig, ax = plt.subplots(figsize=(0.55 * width + 2.2, 0.32 * len(trials) + 1.4))
    ax.imshow(grid, cmap=ListedColormap([OUTCOME_COLOURS[k] for k in keys]), vmin=0, vmax=len(keys) - 1, aspect="auto")
    for row, trial in enumerate(trials):
        for col, outcome in enumerate(trial.outcomes):
            if outcome != "-":
                ax.text(col, row, outcome, ha="center", va="center", color="white", fontsize=8, fontweight="bold")
    ax.set_xticks(range(width), [str(i + 1) for i in range(width)])
    ax.set_yticks(range(len(trials)), [str(i + 1) for i in range(len(trials))])
    ax.set_xlabel("pick")
    ax.set_ylabel("trial")
    names = {"-": "success", "A": "A: missed", "B": "B: slipped", "C": "C: one tip", "": "no pick"}
    ax.legend(handles=[Patch(color=OUTCOME_COLOURS[k], label=names[k]) for k in keys], loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _run_debride(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import dvrk_gym  # noqa: F401
    from dvrk_gym.calibration.policy import CalibratedPolicy
    from dvrk_gym.envs.debridement import fragment_target

    if args.trials < 1:
        raise ValueError(f"--trials must be >= 1, got {args.trials}")
    calibrator, settings = load_calibrator(args.calibration, args.calibrator, args.bias, args.bias_seed)
    bias, bias_seed = settings.get("bias", args.bias), int(settings.get("bias_seed", args.bias_seed))
    env = gym.make(
        "dvrk_gym/Debridement-v0", fragment=args.fragment, bias=bias, bias_seed=bias_seed,
        camera_resolution=tuple(args.resolution),
    )
    try:
        policy = CalibratedPolicy(calibrator, target=fragment_target)
        trials = run_trials(env, policy, args.trials, seed=args.seed, progress=not args.no_progress)
    finally:
        env.close()
    text = format_trial_table(trials, args.calibrator, args.fragment, args.seed)
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = cell_name(args.calibrator, args.fragment)
    meta = {"calibrator": args.calibrator, "fragment": args.fragment, "seed": args.seed, "calibration": str(args.calibration),
            "bias": bias, "bias_seed": bias_seed, "camera_resolution": list(args.resolution)}
    save_trials(trials, args.out / f"{stem}.json", meta)
    (args.out / f"{stem}.txt").write_text(text + "\n")
    label = f"{CALIBRATOR_LABELS[args.calibrator]}, {FRAGMENT_LABELS[args.fragment]}"
    plot_outcome_grid(trials, args.out / f"{stem}.png", f"Debridement outcomes: {label} ({len(trials)} trials)")
    print(f"wrote {args.out / (stem + '.json')}, {args.out / (stem + '.txt')}, {args.out / (stem + '.png')}")
    return 0


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``debride``."""
    debride = subparsers.add_parser(
        "debride",
        help="the paper's debridement trials: pick 8 fragments per trial with a calibrator, judged A/B/C",
        description="Loads a calibrator from a calibration run folder (running the two-phase pipeline there "
        "first if it has no models) and runs debridement trials on Debridement-v0: each pick goes to the next "
        "fragment the endoscope sees, through the calibrator. Prints and writes the paper's trial table "
        "(JSON and text) and a picture of the outcome grid.",
    )
    debride.add_argument("--calibrator", choices=sorted(CALIBRATOR_FILES), default="dnn+rf", help="which calibrator (default: %(default)s)")
    debride.add_argument("--fragment", choices=sorted(FRAGMENT_LABELS), default="pumpkin_seed", help="what to pick (default: %(default)s)")
    debride.add_argument("--trials", type=int, default=15, help="trials of 8 fragments (the paper: %(default)s)")
    debride.add_argument("--calibration", type=Path, default=Path("dvrk_gym_out/calibration"), help="calibration run folder (default: %(default)s)")
    debride.add_argument("--seed", type=int, default=0, help="seeds the trials (default: %(default)s)")
    debride.add_argument("--out", type=Path, default=Path("dvrk_gym_out/debridement"), help="output folder (default: %(default)s)")
    add_instrument_options(debride, note=", if the folder has no run yet")
    add_progress_option(debride)
    debride.set_defaults(func=_run_debride)
