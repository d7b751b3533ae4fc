"""Reinforcement-learning baselines against the two-phase calibrator, for the same robot moves.

Run: python benchmarks/bench_baselines.py [--steps N | --budget calibrator|10x] [--calibration DIR]

Prints (1) training throughput, env steps/s with gradient updates included, for each agent
with one env and with two envs in one process (DummyVecEnv) or two processes
(SubprocVecEnv), at the same gradient updates per env step; (2) the comparison table:
RBT, DNN and DNN+RF from a calibration run folder (``--calibration``, or one run here,
cached in ``--out``) and each agent trained for the budget, all on the same benchmark
(35 circles x 6 yaw settings), with the paper-style table of the agents.

Duration on 2 shared cores: the throughput part a few minutes; the calibrator's budget
(5,476 steps per agent) about 10-20 minutes per agent at 5-10 steps/s under load, plus the
calibration run if none is given (a few minutes); the 10x budget about ten times that.
``--steps`` shortens the training.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dvrk_gym.baselines.agents import AGENTS
from dvrk_gym.baselines.budgets import BUDGETS, resolve_budget
from dvrk_gym.baselines.checkpoints import load_agent, save_agent
from dvrk_gym.baselines.comparison import (
    BENCHMARK_SEED, agent_row, benchmark_agent, calibration_rows, format_comparison, setting_mismatches,
)
from dvrk_gym.baselines.curves import plot_curves, save_curve
from dvrk_gym.baselines.training import TrainConfig, train
from dvrk_gym.calibration.benchmark import format_table
from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration

VEC_SETTINGS = ((1, "dummy"), (2, "dummy"), (2, "subproc"))


def throughput(rate_steps: int, agents: list[str]) -> None:
    """Print training env steps/s per agent and vector-env setting."""
    print(f"Training throughput ({rate_steps} env steps, learning from step 50; evaluations not timed)")
    print(f"{'agent':<10}{'envs':>6}{'vec env':>10}{'env steps/s':>14}")
    for agent in agents:
        for n_envs, vec_env in VEC_SETTINGS:
            config = TrainConfig(agent=agent, steps=rate_steps, n_envs=n_envs, vec_env=vec_env, eval_points=1, overrides={"learning_starts": 50})
            result = train(config, progress=False)
            print(f"{agent:<10}{n_envs:>6}{vec_env:>10}{result.steps_per_second:>14.1f}", flush=True)
    print()


def comparison(args: argparse.Namespace, steps: int) -> None:
    """Train each agent for ``steps``, benchmark it, and print it beside the calibrators."""
    calibration_dir = args.calibration
    if calibration_dir is None:
        calibration_dir = args.out / "calibration"
        start = time.perf_counter()
        run_calibration(calibration_dir, PipelineConfig(seed=args.seed), progress=False)
        print(f"calibration run in {calibration_dir}: {time.perf_counter() - start:.0f} s (cached stages reused)")
    rows, calibration = calibration_rows(calibration_dir)
    table, curves, notes = {}, {}, []
    for agent_name in args.agents:
        config = TrainConfig(agent=agent_name, steps=steps, seed=args.seed, camera_resolution=calibration.camera_resolution, bias=calibration.bias, bias_seed=calibration.bias_seed)
        start = time.perf_counter()
        result = train(config, progress=not args.no_progress)
        path = save_agent(result, args.out / f"{agent_name}_{steps}_seed{args.seed}" / "model.zip")
        save_curve(result.curve, path.parent / "learning_curve.json", {"agent": agent_name, "steps_per_second": result.steps_per_second})
        agent = load_agent(path)
        table[agent_name] = benchmark_agent(agent, seed=BENCHMARK_SEED + calibration.seed)  # the calibrators' touches
        rows.append(agent_row(agent, table[agent_name]))
        curves[agent.label] = result.curve
        notes += setting_mismatches(agent, calibration)
        print(f"{agent_name}: trained {result.env_steps} steps at {result.steps_per_second:.1f} steps/s; with evaluation {time.perf_counter() - start:.0f} s", flush=True)
    plot_curves(curves, args.out / "learning_curves.png", title=f"Agents on GridTouch-v0, seed {args.seed}")
    print()
    print(format_table(table))
    print()
    print(format_comparison(rows, notes))
    print(f"\nwrote models and curves under {args.out}, {args.out / 'learning_curves.png'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", choices=sorted(BUDGETS), default="calibrator", help="training budget (default: %(default)s)")
    parser.add_argument("--steps", type=int, help="train for this many env steps instead of the budget")
    parser.add_argument("--agents", nargs="+", choices=sorted(AGENTS), default=sorted(AGENTS), help="agents (default: all)")
    parser.add_argument("--calibration", type=Path, help="a calibration run folder (default: run one in --out/calibration)")
    parser.add_argument("--out", type=Path, default=Path("dvrk_gym_out/bench_baselines"), help="output folder (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of training and benchmark (default: %(default)s)")
    parser.add_argument("--rate-steps", type=int, default=400, help="env steps per throughput measurement (default: %(default)s)")
    parser.add_argument("--skip-rates", action="store_true", help="skip the throughput measurements")
    parser.add_argument("--skip-comparison", action="store_true", help="only measure throughput")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.skip_rates:
        throughput(args.rate_steps, args.agents)
    if not args.skip_comparison:
        comparison(args, resolve_budget(args.budget, args.steps))


if __name__ == "__main__":
    main()
