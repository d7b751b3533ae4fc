"""The reinforcement-learning baseline commands of ``dvrk-gym``: baseline train, baseline evaluate."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

LOAD_WARNING = (
    "Models are read back without unpickling (the policy weights with torch.load(weights_only=True), "
    "the settings from the JSON beside the zip), but only load model files this tool wrote, or that you trust: "
    "stable-baselines3's own SAC.load would unpickle them."
)


def _run_train(args: argparse.Namespace) -> int:
    from dvrk_gym.baselines.budgets import resolve_budget
    from dvrk_gym.baselines.checkpoints import save_agent
    from dvrk_gym.baselines.curves import plot_curves, save_curve
    from dvrk_gym.baselines.training import TrainConfig, train

    steps = resolve_budget(args.budget, args.steps)
    overrides = {} if args.learning_starts is None else {"learning_starts": args.learning_starts}
    env_overrides = {} if args.reward is None else {"reward_type": args.reward}
    config = TrainConfig(
        agent=args.algo, steps=steps, seed=args.seed, bias=args.bias, bias_seed=args.bias_seed,
        camera_resolution=tuple(args.resolution), training_yaws=args.training_yaws, n_envs=args.n_envs,
        vec_env=args.vec_env, eval_points=args.eval_points, overrides=overrides, env_overrides=env_overrides,
    )
    out = args.out or Path("dvrk_gym_out/baselines") / f"{args.algo}_{args.budget if args.steps is None else steps}_seed{args.seed}"
    out.mkdir(parents=True, exist_ok=True)
    result = train(config, progress=not args.no_progress)
    model_path = save_agent(result, out / "model.zip")
    label = f"{args.algo}, seed {args.seed}"
    meta = {"agent": args.algo, "seed": args.seed, "env_steps": result.env_steps, "steps_per_second": result.steps_per_second}
    save_curve(result.curve, out / "learning_curve.json", meta)
    plot_curves({label: result.curve}, out / "learning_curve.png", title=f"{args.algo} on GridTouch-v0 (bias {args.bias}, seed {args.seed})")
    final = result.curve[-1]
    print(f"{args.algo}: {result.env_steps} env steps in {result.train_seconds:.0f} s ({result.steps_per_second:.1f} steps/s; evaluations {result.eval_seconds:.0f} s more)")
    print(f"learning curve: {result.curve[0].mm_error:.2f} mm at 0 steps -> {final.mm_error:.2f} mm ({final.pixel_error:.1f} px) at {final.env_steps}")
    print(f"wrote {model_path}, {model_path.with_suffix('.json')}, {out / 'learning_curve.json'}, {out / 'learning_curve.png'}")
    return 0


def _run_evaluate(args: argparse.Namespace) -> int:
    from dvrk_gym.baselines.checkpoints import load_agent
    from dvrk_gym.baselines.comparison import (
        BENCHMARK_SEED, agent_row, benchmark_agent, calibration_rows, format_comparison, setting_mismatches,
    )
    from dvrk_gym.calibration.benchmark import format_table, save_table

    agents = [load_agent(path) for path in args.model]
    labels = [agent.label for agent in agents]
    if len(set(labels)) < len(labels):
        raise ValueError(f"two models have the same agent, steps and seed ({labels}); give each once")
    rows, calibration = calibration_rows(args.calibration) if args.calibration is not None else ([], None)
    seed = args.seed if args.seed is not None else (calibration.seed if calibration is not None else 0)
    names = [agent.config.agent for agent in agents]
    keys = names if len(set(names)) == len(names) else [f"{name}#{i + 1}" for i, name in enumerate(names)]  # short, for the paper's table
    table = {key: benchmark_agent(agent, seed=BENCHMARK_SEED + seed, progress=not args.no_progress) for key, agent in zip(keys, agents)}
    text = format_table(table) + "\n" + "\n".join(f"{key}: {agent.label}, {agent.path}" for key, agent in zip(keys, agents))
    print(text)
    args.out.mkdir(parents=True, exist_ok=True)
    save_table(table, args.out / "baseline_table.json")
    (args.out / "baseline_table.txt").write_text(text + "\n")
    written = [args.out / "baseline_table.json", args.out / "baseline_table.txt"]
    if calibration is not None:
        rows += [agent_row(agent, table[key]) for key, agent in zip(keys, agents)]
        notes = [note for agent in agents for note in setting_mismatches(agent, calibration)]
        comparison = format_comparison(rows, notes)
        print()
        print(comparison)
        (args.out / "comparison.txt").write_text(comparison + "\n")
        (args.out / "comparison.json").write_text(json.dumps({"rows": [row.__dict__ for row in rows], "notes": notes}, indent=1))
        written += [args.out / "comparison.txt", args.out / "comparison.json"]
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _add_train(subparsers: argparse._SubParsersAction) -> None:
    from dvrk_gym.baselines.agents import AGENTS
    from dvrk_gym.baselines.budgets import BUDGETS

    train = subparsers.add_parser(
        "train",
        help="train an agent on GridTouch-v0 for a budget of robot moves",
        description="Train an agent on GridTouch-v0 (one touch per env step) and save the model (SB3 zip + settings JSON), "
        "its learning curve (JSON) and a plot of evaluation error against env steps. Agents: "
        + "; ".join(f"{name}: {spec.description}" for name, spec in AGENTS.items())
        + ". Budgets: " + ", ".join(f"{name} = {steps:,} env steps" for name, steps in BUDGETS.items()) + ".",
    )
    train.add_argument("--algo", choices=sorted(AGENTS), default="sac_her", help="the agent (default: %(default)s)")
    train.add_argument("--budget", choices=sorted(BUDGETS), default="calibrator", help="env steps, matched to the calibrator's robot moves (default: %(default)s)")
    train.add_argument("--steps", type=int, help="an explicit number of env steps (overrides --budget), for tests and quick runs")
    train.add_argument("--seed", type=int, default=0, help="seeds the model and the envs (default: %(default)s)")
    train.add_argument("--out", type=Path, help="output folder (default: dvrk_gym_out/baselines/<algo>_<budget>_seed<seed>)")
    train.add_argument("--bias", default="paper", help="cable bias preset: none, paper or severe (default: %(default)s)")
    train.add_argument("--bias-seed", type=int, default=0, help="which instrument to draw (default: %(default)s)")
    train.add_argument("--resolution", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"), help="endoscope image size; evaluate at the same (default: 1920 1080)")
    train.add_argument("--training-yaws", choices=("paper", "random"), default="paper", help="yaws of the training touches: a tour of the circles per paper yaw, or random (default: %(default)s)")
    train.add_argument("--reward", choices=("dense", "sparse"), help="GridTouch reward (default: the agent's, dense)")
    train.add_argument("--n-envs", type=int, default=1, help="parallel training envs (default: %(default)s; 1 was fastest on 2 cores)")
    train.add_argument("--vec-env", choices=("dummy", "subproc"), default="dummy", help="vector env for --n-envs > 1 (default: %(default)s)")
    train.add_argument("--learning-starts", type=int, help="random moves before learning (default: the agent's, 200)")
    train.add_argument("--eval-points", type=int, default=20, help="evaluations along the learning curve (default: %(default)s)")
    train.add_argument("--no-progress", action="store_true", help="no progress bar")
    train.set_defaults(func=_run_train)


def _add_evaluate(subparsers: argparse._SubParsersAction) -> None:
    evaluate = subparsers.add_parser(
        "evaluate",
        help="the calibrators' benchmark (35 circles x 6 yaw settings) for trained agents, and a comparison table",
        description="Run trained agents through the calibrators' benchmark (35 circles x 6 yaw settings, the same "
        "touch_grid protocol and seeds as 'dvrk-gym evaluate'), print the paper-style table, and with --calibration "
        "a comparison of error against robot moves with RBT, DNN and DNN+RF. " + LOAD_WARNING,
    )
    evaluate.add_argument("--model", type=Path, nargs="+", required=True, help="model.zip file(s) written by 'baseline train' (with their .json beside)")
    evaluate.add_argument("--out", type=Path, default=Path("dvrk_gym_out/baselines/evaluation"), help="output folder (default: %(default)s)")
    evaluate.add_argument("--calibration", type=Path, help="a calibration run folder with calibration_table.json (from 'dvrk-gym evaluate')")
    evaluate.add_argument("--seed", type=int, help="benchmark seed, as a calibration run's --seed (default: the --calibration run's, else 0)")
    evaluate.add_argument("--no-progress", action="store_true", help="no progress bar")
    evaluate.set_defaults(func=_run_evaluate)


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``baseline`` with its sub-commands ``train`` and ``evaluate``."""
    baseline = subparsers.add_parser("baseline", help="reinforcement-learning baselines (SAC+HER, SAC) against the calibrators")
    commands = baseline.add_subparsers(dest="baseline_command", required=True, metavar="SUBCOMMAND")
    _add_train(commands)
    _add_evaluate(commands)
