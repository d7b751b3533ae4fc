"""The reinforcement-learning baseline commands of ``dvrk-gym``: baseline train, baseline evaluate.

Everything heavy (torch, stable-baselines3, pybullet) is imported inside the commands, so
that ``dvrk-gym baseline --help`` stays fast.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import DEFAULT_EVAL_POINTS, MAX_EVAL_POINTS
from dvrk_gym.cli.options import add_instrument_options, add_progress_option, writable_folder
from dvrk_gym.utils.atomic import atomic_write_json, atomic_write_text
from dvrk_gym.utils.checks import check_int
from dvrk_gym.utils.run_folder import RunFolder

if TYPE_CHECKING:
    from dvrk_gym.baselines.curves import CurvePoint

TRAINING_STATE = "training_state.zip"
"""The file in a training's output folder that holds its state until its outputs are written
(``dvrk_gym.baselines.resume.STATE_FILE_NAME``, which a test checks; repeated here so that
``--help`` does not import torch)."""
OUTPUTS = ("model.zip", "model.json", "learning_curve.json", "learning_curve.png")
"""What a finished training leaves in its folder (a folder holding them all is not trained again without ``--force``)."""
DEFAULT_SAVE_EVERY = 500
"""``--save-every``'s default (``dvrk_gym.baselines.training.SAVE_EVERY``, which a test checks;
repeated here so that ``--help`` does not import torch)."""
LOAD_WARNING = (
    "Models are read back without unpickling (the policy weights with torch.load(weights_only=True), "
    "the settings from the JSON beside the zip), but only load model files this tool wrote, or that you trust: "
    "stable-baselines3's own SAC.load would unpickle them."
)


def training_folder(args: argparse.Namespace) -> Path:
    """Where ``baseline train`` writes: ``--out``, else ``dvrk_gym_out/baselines/<algo>_<budget or --steps>_seed<seed>``."""
    label = args.budget if args.steps is None else args.steps
    return args.out or Path("dvrk_gym_out/baselines") / f"{args.algo}_{label}_seed{args.seed}"


def _run_train(args: argparse.Namespace) -> int:
    from dvrk_gym.baselines.budgets import AGENT_ENVS, DEBRIDEMENT_ID, resolve_budget
    from dvrk_gym.baselines.checkpoints import finished_agent, save_agent
    from dvrk_gym.baselines.curves import load_curve, plot_curves, save_curve
    from dvrk_gym.baselines.resume import TrainingStateError
    from dvrk_gym.baselines.training import TrainConfig, train

    if args.steps is not None:
        check_int("--steps", args.steps, 1, 10**9)
    save_every = check_int("--save-every", args.save_every, 1, 10**9)
    steps = resolve_budget(args.budget, args.steps)
    eval_points = DEFAULT_EVAL_POINTS if args.eval_points is None else check_int("--eval-points", args.eval_points, 1, MAX_EVAL_POINTS)
    if args.eval_points is not None and eval_points > steps:
        raise ValueError(
            f"--eval-points {eval_points} is more than the {steps} env steps trained: a learning curve has at most one point a step"
        )
    picks = AGENT_ENVS[args.algo] == DEBRIDEMENT_ID
    if picks and args.reward is not None:
        raise ValueError(f"--reward chooses GridTouch's reward; {args.algo} learns Debridement-v0 with its shaped pick reward")
    if not picks and args.fragment is not None:
        raise ValueError(f"--fragment is for the pick agents; {args.algo} learns GridTouch-v0")
    overrides = {} if args.learning_starts is None else {"learning_starts": check_int("--learning-starts", args.learning_starts, 0, 10**9)}
    env_overrides = {} if args.reward is None else {"reward_type": args.reward}
    if args.fragment is not None:
        env_overrides["fragment"] = args.fragment
    config = TrainConfig(
        agent=args.algo,
        steps=steps,
        seed=args.seed,
        bias=args.bias,
        bias_seed=args.bias_seed,
        camera_resolution=tuple(args.resolution),
        training_yaws=args.training_yaws,
        n_envs=args.n_envs,
        vec_env=args.vec_env,
        eval_points=eval_points,
        overrides=overrides,
        env_overrides=env_overrides,
    )
    out = training_folder(args)
    writable_folder(out)  # before training: a folder that cannot hold the model is found now, not after the training
    state_path = out / TRAINING_STATE
    # The folder is this process's while it trains (a second training there is refused, naming
    # this one), and the temporary file of a save cut short by a kill is removed.
    with RunFolder(out):
        if args.force:
            state_path.unlink(missing_ok=True)  # train from the start: a saved state would be resumed
        resuming = state_path.exists()
        if not resuming and all((out / name).exists() for name in OUTPUTS):
            if finished_agent(out / "model.zip", config) is None:
                raise FileExistsError(
                    f"{out / 'model.zip'} exists: {out} holds a finished training of other settings or other code "
                    "(or a damaged one); give --force to train again, or another --out"
                )
            try:
                curve = load_curve(out / "learning_curve.json")
                if not curve:
                    raise ValueError(f"{out / 'learning_curve.json'} holds no points")
            except ValueError as error:
                raise ValueError(f"{error}; give --force to train again") from None
            _print_curve(curve, picks=picks)
            print(f"{out} holds this training, finished with these settings by this code: nothing to do (--force trains again)")
            return 0
        # killed between its outputs before any save: the same training writes the same ones
        if not resuming and (out / "model.zip").exists():
            print(f"{out} holds a model but not all of {', '.join(OUTPUTS)}, and no saved state: training again from the start")
        try:
            result = train(config, progress=not args.no_progress, state_path=state_path, save_every=save_every)
        except TrainingStateError as error:
            raise TrainingStateError(f"{error} (--force trains from the start, replacing it)") from None
        if resuming:  # said once the state was found to be this training's (a state of other settings is refused)
            print(f"resumed the training saved in {state_path}")
        model_path = save_agent(result, out / "model.zip")  # the model first: nothing after it can lose it
        label = f"{args.algo}, seed {args.seed}"
        meta = {"agent": args.algo, "seed": args.seed, "env_steps": result.env_steps, "steps_per_second": result.steps_per_second}
        save_curve(result.curve, out / "learning_curve.json", meta)
        env_name = AGENT_ENVS[args.algo].split("/")[-1]
        plot_curves(
            {label: result.curve},
            out / "learning_curve.png",
            title=f"{args.algo} on {env_name} (bias {args.bias}, seed {args.seed})",
            metric="success_rate" if picks else "mm_error",
        )
        # Every output is written: the saved state is not needed any more. (Killed before this,
        # the same command resumes from it and writes them all again.)
        state_path.unlink(missing_ok=True)
    print(
        f"{args.algo}: {result.env_steps} env steps in {result.train_seconds:.0f} s "
        f"({result.steps_per_second:.2f} steps/s; evaluations {result.eval_seconds:.0f} s more)"
    )
    _print_curve(result.curve, picks=picks)
    print(f"wrote {model_path}, {model_path.with_suffix('.json')}, {out / 'learning_curve.json'}, {out / 'learning_curve.png'}")
    return 0


def _print_curve(curve: Sequence[CurvePoint], *, picks: bool) -> None:
    """One line: the learning curve's first and last points (touch error, or pick success)."""
    first, final = curve[0], curve[-1]
    if picks:
        print(
            f"learning curve: success {first.success_rate:.0%}, grip offset {first.mm_error:.2f} mm at 0 steps -> "
            f"success {final.success_rate:.0%}, {final.mm_error:.2f} mm, "
            f"{final.time_per_fragment_s:.2f} s per fragment at {final.env_steps}"
        )
    else:
        print(
            f"learning curve: {first.mm_error:.2f} mm at 0 steps -> "
            f"{final.mm_error:.2f} mm ({final.pixel_error:.1f} px) at {final.env_steps}"
        )


def _run_evaluate(args: argparse.Namespace) -> int:
    from dvrk_gym.baselines.budgets import GRID_TOUCH_ID
    from dvrk_gym.baselines.checkpoints import distinct_labels, load_agent
    from dvrk_gym.baselines.comparison import check_calibration_folder

    if args.trials < 1:
        raise ValueError(f"--trials must be >= 1, got {args.trials}")
    writable_folder(args.out)
    agents = distinct_labels([load_agent(path) for path in args.model])  # two trained alike but for --bias...: named apart
    written: list[Path] = []
    grid_agents = [agent for agent in agents if agent.config.spec.env_id == GRID_TOUCH_ID]
    debriding = [agent for agent in agents if agent.config.spec.env_id != GRID_TOUCH_ID or args.transfer]
    if args.calibration is not None:  # all of it before any part runs and writes its files
        check_calibration_folder(args.calibration, table=bool(grid_agents), models=bool(debriding))
    if grid_agents:
        written += _evaluate_touch_grid(grid_agents, args)
    if debriding:
        written += _evaluate_debridement(debriding, args)
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _evaluate_touch_grid(agents: list, args: argparse.Namespace) -> list[Path]:
    """The calibrators' touch-grid benchmark for GridTouch agents, and the comparison with --calibration."""
    from dvrk_gym.baselines.comparison import (
        BENCHMARK_SEED,
        agent_row,
        benchmark_agent,
        calibration_rows,
        env_change_notes,
        format_comparison,
        setting_mismatches,
    )
    from dvrk_gym.calibration.benchmark import format_table, save_table

    rows, calibration = calibration_rows(args.calibration) if args.calibration is not None else ([], None)
    seed = args.seed if args.seed is not None else (calibration.seed if calibration is not None else 0)
    names = [agent.config.agent for agent in agents]
    keys = names if len(set(names)) == len(names) else [f"{name}#{i + 1}" for i, name in enumerate(names)]  # short, for the paper's table
    table = {key: benchmark_agent(agent, seed=BENCHMARK_SEED + seed, progress=not args.no_progress) for key, agent in zip(keys, agents)}
    changes = [f"note: {note}" for agent in agents for note in env_change_notes(agent)]
    text = format_table(table) + "\n" + "\n".join([*(f"{key}: {agent.label}, {agent.path}" for key, agent in zip(keys, agents)), *changes])
    print(text)
    save_table(table, args.out / "baseline_table.json", notes=[note for agent in agents for note in env_change_notes(agent)])
    atomic_write_text(args.out / "baseline_table.txt", text + "\n")
    written = [args.out / "baseline_table.json", args.out / "baseline_table.txt"]
    if calibration is not None:
        rows += [agent_row(agent, table[key]) for key, agent in zip(keys, agents)]
        notes = [note for agent in agents for note in setting_mismatches(agent, calibration)]
        if seed != calibration.seed:  # the calibrators' rows are the run's own benchmark, at its seed
            notes.append(
                f"the agents were benchmarked with --seed {seed}, the calibrators' rows with the calibration run's seed "
                f"{calibration.seed}: other random yaws (leave --seed out to use the run's)"
            )
        comparison = format_comparison(rows, notes)
        print()
        print(comparison)
        atomic_write_text(args.out / "comparison.txt", comparison + "\n")
        atomic_write_json(args.out / "comparison.json", {"rows": [row.__dict__ for row in rows], "notes": notes}, indent=1)
        written += [args.out / "comparison.txt", args.out / "comparison.json"]
    return written


def _evaluate_debridement(agents: list, args: argparse.Namespace) -> list[Path]:
    """Debridement trials for pick agents (and transferred GridTouch agents), beside the calibrators' with --calibration."""
    from dvrk_gym.baselines.comparison import (
        benchmark_debridement,
        calibration_debridement_rows,
        debridement_row,
        env_change_notes,
        format_debridement_comparison,
        setting_mismatches,
    )
    from dvrk_gym.evaluation.trials import format_trial_table

    seed = args.seed if args.seed is not None else 0
    texts, rows = [], []
    notes = [note for agent in agents for note in env_change_notes(agent, picks=True)]
    for agent in agents:
        trials = benchmark_debridement(agent, args.trials, seed=seed, fragment=args.fragment, progress=not args.no_progress)
        texts.append(format_trial_table(trials, agent.label, args.fragment, seed))
        rows.append(debridement_row(agent.label, agent.env_steps, trials, str(agent.path)))
    calibrators_resolution = None
    if args.calibration is not None:  # the calibrators run at the resolution they were calibrated at; agents at others are noted
        calibrators, calibration = calibration_debridement_rows(
            args.calibration, n_trials=args.trials, seed=seed, fragment=args.fragment, progress=not args.no_progress
        )
        calibrators_resolution = list(calibration.camera_resolution)
        rows = calibrators + rows
        notes = [note for agent in agents for note in setting_mismatches(agent, calibration, picks=True)]
    text = "\n\n".join(texts + [format_debridement_comparison(rows, notes)])
    print()
    print(text)
    atomic_write_text(args.out / "debridement.txt", text + "\n")
    data = {
        "seed": seed,
        "trials": args.trials,
        "fragment": args.fragment,
        "calibrators_camera_resolution": calibrators_resolution,
        "rows": [{**row.__dict__, "success_rate": row.success_rate} for row in rows],
        "notes": notes,
    }
    atomic_write_json(args.out / "debridement.json", data, indent=1)
    return [args.out / "debridement.txt", args.out / "debridement.json"]


def _add_train(subparsers: argparse._SubParsersAction) -> None:
    from dvrk_gym.baselines.budgets import AGENT_DESCRIPTIONS as AGENTS
    from dvrk_gym.baselines.budgets import BUDGETS

    train = subparsers.add_parser(
        "train",
        help="train an agent (GridTouch-v0 touches or Debridement-v0 picks) for a budget of robot moves",
        description="Train an agent on GridTouch-v0 (one touch per env step) or Debridement-v0 (one pick per env step) and "
        "save the model (SB3 zip + settings JSON), its learning curve (JSON) and a plot of it against env steps "
        "(touch error; debridement success). Agents: "
        + "; ".join(f"{name}: {description}" for name, description in AGENTS.items())
        + ". Budgets: "
        + ", ".join(f"{name} = {steps:,} env steps" for name, steps in BUDGETS.items())
        + ".",
    )
    train.add_argument("--algo", choices=sorted(AGENTS), default="sac_her", help="the agent (default: %(default)s)")
    train.add_argument(
        "--budget",
        choices=sorted(BUDGETS),
        default="calibrator",
        help="env steps, matched to the calibrator's robot moves (default: %(default)s)",
    )
    train.add_argument("--steps", type=int, help="an explicit number of env steps (overrides --budget), for tests and quick runs")
    train.add_argument("--seed", type=int, default=0, help="seeds the model and the envs (default: %(default)s)")
    train.add_argument("--out", type=Path, help="output folder (default: dvrk_gym_out/baselines/<algo>_<budget or --steps>_seed<seed>)")
    add_instrument_options(train)
    train.add_argument(
        "--training-yaws",
        choices=("paper", "random"),
        default="paper",
        help="yaws of the training touches: a tour of the circles per paper yaw, or random (default: %(default)s)",
    )
    train.add_argument("--reward", choices=("dense", "sparse"), help="GridTouch reward (default: the agent's, dense)")
    train.add_argument("--fragment", choices=sorted(paper.FRAGMENT_LABELS), help="pick agents: what to pick (default: pumpkin_seed)")
    train.add_argument("--n-envs", type=int, default=1, help="parallel training envs (default: %(default)s; 1 was fastest on 2 cores)")
    train.add_argument(
        "--vec-env", choices=("dummy", "subproc"), default="dummy", help="vector env for --n-envs > 1 (default: %(default)s)"
    )
    train.add_argument("--learning-starts", type=int, help="random moves before learning (default: the agent's, 200; sac_pick 100)")
    train.add_argument(
        "--eval-points",
        type=int,
        help=f"evaluations along the learning curve, at most one per env step (default: {DEFAULT_EVAL_POINTS}; fewer if shorter)",
    )
    train.add_argument(
        "--save-every",
        type=int,
        default=DEFAULT_SAVE_EVERY,
        help=f"env steps between saves of the training's state to OUT/{TRAINING_STATE} (default: %(default)s; at each multiple of it, "
        "or at the first moment after it when every training env is between episodes); a killed run given the same "
        "command resumes from it and ends with the weights, optimiser states and learning curve of a run never stopped, bit "
        "for bit (not SB3's logging statistics of recent episodes); it is deleted once every output is written",
    )
    train.add_argument(
        "--force",
        action="store_true",
        help=(
            "train from the start even if --out holds a finished training (its model.zip) or a saved state; both are replaced "
            "(without it, a training finished there with the same settings is reported, not trained again)"
        ),
    )
    add_progress_option(train)
    train.set_defaults(func=_run_train)


def _add_evaluate(subparsers: argparse._SubParsersAction) -> None:
    evaluate = subparsers.add_parser(
        "evaluate",
        help="the calibrators' benchmarks (touch grid; debridement trials) for trained agents, and comparison tables",
        description="Run trained GridTouch agents through the calibrators' benchmark (35 circles x 6 yaw settings, the same "
        "touch_grid passes and seeds as 'dvrk-gym evaluate'; an agent's commands are sent as they are, where evaluate lifts "
        "the rigid body's as the paper's runs did) and print the paper-style table; run pick agents (and, with "
        "--transfer, GridTouch agents aimed at the fragments) through debridement trials of 8 picks (success, A/B/C, time "
        "per fragment). With --calibration, the calibrators' rows beside them: their touch errors from the run's table, and "
        "their debridement trials run here with the same seeds (as 'dvrk-gym debride'). " + LOAD_WARNING,
    )
    evaluate.add_argument(
        "--model", type=Path, nargs="+", required=True, help="model.zip file(s) written by 'baseline train' (with their .json beside)"
    )
    evaluate.add_argument(
        "--out", type=Path, default=Path("dvrk_gym_out/baselines/evaluation"), help="output folder (default: %(default)s)"
    )
    evaluate.add_argument(
        "--calibration", type=Path, help="a calibration run folder with calibration_table.json (from 'dvrk-gym evaluate')"
    )
    evaluate.add_argument(
        "--seed",
        type=int,
        help="touch grid: benchmark seed, as a calibration run's --seed (default: the --calibration run's, else 0); "
        "debridement: the trials' seed (default 0)",
    )
    evaluate.add_argument(
        "--trials",
        type=int,
        default=paper.DEBRIDEMENT_TRIALS,
        help="debridement trials of 8 picks per method (default: %(default)s, the paper's)",
    )
    evaluate.add_argument(
        "--fragment", choices=sorted(paper.FRAGMENT_LABELS), default="pumpkin_seed", help="debridement: what to pick (default: %(default)s)"
    )
    evaluate.add_argument(
        "--transfer", action="store_true", help="also run GridTouch agents through the debridement trials (aimed by pick_policy)"
    )
    add_progress_option(evaluate)
    evaluate.set_defaults(func=_run_evaluate)


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``baseline`` with its sub-commands ``train`` and ``evaluate``."""
    baseline = subparsers.add_parser(
        "baseline", help="reinforcement-learning baselines (SAC+HER, SAC, SAC on picks) against the calibrators"
    )
    commands = baseline.add_subparsers(dest="baseline_command", required=True, metavar="SUBCOMMAND")
    _add_train(commands)
    _add_evaluate(commands)
