"""Reinforcement-learning baselines against the two-phase calibrator, for the same robot moves.

Run: python benchmarks/bench_baselines.py [--steps N | --budget calibrator|10x] [--calibration DIR]
     [--agents sac_her sac sac_pick] [--models model.zip ...] [--trials 15]

Prints (1) training throughput, env steps/s with gradient updates included: each GridTouch
agent with one env and with two envs in one process (DummyVecEnv) or two processes
(SubprocVecEnv), at the same gradient updates per env step; each pick agent with one env;
(2) the wall time of one Debridement-v0 pick at several camera resolutions (aimed by the
DNN+RF calibrator); (3) the comparison tables: RBT, DNN and DNN+RF from a calibration run
folder (``--calibration``, or one run here, cached in ``--out``) and each agent trained for
the budget (``--agents``) or given (``--models``): the touch grid (35 circles x 6 yaw
settings, mm and px) for the GridTouch agents, with the paper-style table; and the
debridement trials (success, A/B/C, time per fragment) for every agent (GridTouch agents
through ``pick_policy``) and the calibrators, with the same seeds.

Duration on 2 shared cores: the throughput part a few minutes; the calibrator's budget
(5,476 steps) about 10-20 minutes per GridTouch agent at 5-10 steps/s under load, and
about 45-90 minutes for a pick agent at 1-2 picks/s; the calibration run if none is given
(a few minutes); the debridement trials about a minute per method (15 trials); the 10x
budget about ten times the training. ``--steps`` shortens the training. Each agent's
training saves its state in its folder under ``--out`` (``training_state.zip``), so the same
command, killed, resumes the training it was in (:mod:`dvrk_gym.baselines.resume`) and keeps
the agents it had finished, when this code trained them with these settings
(:func:`dvrk_gym.baselines.checkpoints.finished_agent`; delete an agent's folder to train it
again).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

from dvrk_gym.baselines.agents import AGENTS
from dvrk_gym.baselines.budgets import BUDGETS, DEBRIDEMENT_ID, GRID_TOUCH_ID, resolve_budget
from dvrk_gym.baselines.checkpoints import LoadedAgent, finished_agent, load_agent, save_agent
from dvrk_gym.baselines.comparison import (
    BENCHMARK_SEED,
    agent_row,
    benchmark_agent,
    benchmark_debridement,
    calibration_debridement_rows,
    calibration_rows,
    debridement_row,
    format_comparison,
    format_debridement_comparison,
    setting_mismatches,
)
from dvrk_gym.baselines.curves import CurvePoint, load_curve, plot_curves, save_curve
from dvrk_gym.baselines.resume import STATE_FILE_NAME
from dvrk_gym.baselines.training import TrainConfig, train
from dvrk_gym.calibration.benchmark import format_table
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.envs.debridement import fragment_target

VEC_SETTINGS = ((1, "dummy"), (2, "dummy"), (2, "subproc"))
PICK_RESOLUTIONS = ((1920, 1080), (960, 540), (640, 360), (320, 180))


def is_pick_agent(name: str) -> bool:
    return AGENTS[name].env_id == DEBRIDEMENT_ID


def throughput(rate_steps: int, pick_rate_steps: int, agents: list[str]) -> None:
    """Print training env steps/s per agent and vector-env setting."""
    print(
        f"Training throughput (GridTouch agents {rate_steps} env steps, pick agents {pick_rate_steps}; "
        "learning from step 50; evaluations not timed)"
    )
    print(f"{'agent':<10}{'envs':>6}{'vec env':>10}{'env steps/s':>14}")
    for agent in agents:
        picks = is_pick_agent(agent)
        for n_envs, vec_env in VEC_SETTINGS[:1] if picks else VEC_SETTINGS:
            steps = pick_rate_steps if picks else rate_steps
            config = TrainConfig(
                agent=agent, steps=steps, n_envs=n_envs, vec_env=vec_env, eval_points=1, curve_trials=1, overrides={"learning_starts": 50}
            )
            result = train(config, progress=False)
            print(f"{agent:<10}{n_envs:>6}{vec_env:>10}{result.steps_per_second:>14.2f}", flush=True)
    print()


def pick_timing(calibration_dir: Path, resolutions: list[tuple[int, int]], trials: int) -> None:
    """Print the wall time of a Debridement-v0 pick (env.step) per camera resolution, DNN+RF aiming."""
    calibrator, settings = load_calibrator(calibration_dir, "dnn+rf")
    policy = CalibratedPolicy(calibrator, target=fragment_target)
    print(f"Wall time of one pick (env.step, {trials} trial(s) of 8 picks, DNN+RF aiming) and of a reset")
    print(f"{'resolution':>12}{'s per pick':>12}{'sd':>8}{'s per reset':>13}{'success':>10}")
    for width, height in resolutions:
        env = gym.make(DEBRIDEMENT_ID, camera_resolution=(width, height), bias=settings["bias"], bias_seed=settings["bias_seed"])
        steps, resets, successes = [], [], 0
        try:
            for trial in range(trials):
                start = time.perf_counter()
                observation, _ = env.reset(seed=trial)
                resets.append(time.perf_counter() - start)
                done = False
                while not done:
                    action = policy(observation)
                    start = time.perf_counter()
                    observation, reward, terminated, truncated, _ = env.step(action)
                    steps.append(time.perf_counter() - start)
                    successes += int(reward)
                    done = terminated or truncated
        finally:
            env.close()
        print(
            f"{f'{width}x{height}':>12}{np.mean(steps):>12.3f}{np.std(steps):>8.3f}{np.mean(resets):>13.3f}{f'{successes}/{len(steps)}':>10}",
            flush=True,
        )
    print()


def _finished(folder: Path, config: TrainConfig) -> tuple[LoadedAgent, list[CurvePoint]] | None:
    """The agent and learning curve a killed run of this command finished in ``folder``, if
    they are ``config``'s and this code's (:func:`finished_agent`); None: train it."""
    if (folder / STATE_FILE_NAME).exists():
        return None  # its training was cut short: resume it
    agent = finished_agent(folder / "model.zip", config)
    try:
        return None if agent is None else (agent, load_curve(folder / "learning_curve.json"))
    except (OSError, ValueError, TypeError, KeyError):
        return None  # no curve, or a damaged one: train again


def train_agents(args: argparse.Namespace, steps: int, pick_steps: int, calibration: PipelineConfig) -> list[LoadedAgent]:
    """Train each of ``args.agents``, save it with its curve, and load it back."""
    agents, curves = [], {}
    for agent_name in args.agents:
        budget = pick_steps if is_pick_agent(agent_name) else steps
        config = TrainConfig(
            agent=agent_name,
            steps=budget,
            seed=args.seed,
            camera_resolution=calibration.camera_resolution,
            bias=calibration.bias,
            bias_seed=calibration.bias_seed,
        )
        folder = args.out / f"{agent_name}_{budget}_seed{args.seed}"
        folder.mkdir(parents=True, exist_ok=True)
        kept = _finished(folder, config)
        if kept is not None:  # this run was killed after it: its model and curve are this code's and these settings'
            agent, curve = kept
            curves.setdefault(is_pick_agent(agent_name), {})[f"{agent_name}, seed {args.seed}"] = curve
            print(f"{agent_name}: kept the agent this command trained before in {folder} (delete the folder to train it again)")
            agents.append(agent)
            continue
        start = time.perf_counter()
        result = train(config, progress=not args.no_progress, state_path=folder / STATE_FILE_NAME)  # a killed run resumes
        path = save_agent(result, folder / "model.zip")
        save_curve(result.curve, path.parent / "learning_curve.json", {"agent": agent_name, "steps_per_second": result.steps_per_second})
        (folder / STATE_FILE_NAME).unlink(missing_ok=True)  # its outputs are written
        curves.setdefault(is_pick_agent(agent_name), {})[f"{agent_name}, seed {args.seed}"] = result.curve
        print(
            f"{agent_name}: trained {result.env_steps} steps at {result.steps_per_second:.2f} steps/s in {result.train_seconds:.0f} s; "
            f"with evaluations {time.perf_counter() - start:.0f} s",
            flush=True,
        )
        agents.append(load_agent(path))
    for picks, group in curves.items():
        name = "learning_curves_debridement.png" if picks else "learning_curves.png"
        plot_curves(
            group,
            args.out / name,
            title=f"Agents on {'Debridement' if picks else 'GridTouch'}-v0, seed {args.seed}",
            metric="success_rate" if picks else "mm_error",
        )
    return agents


def comparison(args: argparse.Namespace, steps: int, pick_steps: int) -> None:
    """Train or load the agents, and print them beside the calibrators on both benchmarks."""
    calibration_dir = args.calibration
    if calibration_dir is None:
        calibration_dir = args.out / "calibration"
        start = time.perf_counter()
        run_calibration(calibration_dir, PipelineConfig(seed=args.seed), progress=False)
        print(f"calibration run in {calibration_dir}: {time.perf_counter() - start:.0f} s (cached stages reused)")
    if not args.skip_rates:
        pick_timing(calibration_dir, PICK_RESOLUTIONS, args.timing_trials)
    rows, calibration = calibration_rows(calibration_dir)
    agents = train_agents(args, steps, pick_steps, calibration) + [load_agent(path) for path in args.models]
    notes = [note for agent in agents for note in setting_mismatches(agent, calibration)]

    grid_agents = [agent for agent in agents if agent.config.spec.env_id == GRID_TOUCH_ID]
    if grid_agents:
        names = [agent.config.agent for agent in grid_agents]
        keys = names if len(set(names)) == len(names) else [f"{name}#{i + 1}" for i, name in enumerate(names)]
        table = {
            key: benchmark_agent(agent, seed=BENCHMARK_SEED + calibration.seed) for key, agent in zip(keys, grid_agents)
        }  # the calibrators' touches
        rows += [agent_row(agent, table[key]) for key, agent in zip(keys, grid_agents)]
        print()
        print(format_table(table))
        print("\n".join(f"{key}: {agent.label}, {agent.path}" for key, agent in zip(keys, grid_agents)))
        print()
        print(format_comparison(rows, notes))

    start = time.perf_counter()
    debridement, _ = calibration_debridement_rows(
        calibration_dir, n_trials=args.trials, seed=0, camera_resolution=calibration.camera_resolution
    )
    for agent in agents:
        label = agent.label + (" via pick_policy" if agent.config.spec.env_id == GRID_TOUCH_ID else "")
        debridement.append(debridement_row(label, agent.env_steps, benchmark_debridement(agent, args.trials, seed=0), str(agent.path)))
    print()
    pick_notes = [note for agent in agents for note in setting_mismatches(agent, calibration, picks=True)]
    print(format_debridement_comparison(debridement, pick_notes))
    print(f"(debridement trials: {time.perf_counter() - start:.0f} s)")
    print(f"\nwrote models and curves under {args.out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", choices=sorted(BUDGETS), default="calibrator", help="training budget (default: %(default)s)")
    parser.add_argument("--steps", type=int, help="train the GridTouch agents for this many env steps instead of the budget")
    parser.add_argument("--pick-steps", type=int, help="train the pick agents for this many picks instead of the budget")
    parser.add_argument(
        "--agents",
        nargs="*",
        choices=sorted(AGENTS),
        default=sorted(AGENTS),
        help="agents to train (default: all; none with --agents and no names)",
    )
    parser.add_argument("--models", nargs="*", type=Path, default=[], help="trained model.zip files to include as they are")
    parser.add_argument("--calibration", type=Path, help="a calibration run folder (default: run one in --out/calibration)")
    parser.add_argument("--out", type=Path, default=Path("dvrk_gym_out/bench_baselines"), help="output folder (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of training and touch-grid benchmark (default: %(default)s)")
    parser.add_argument("--trials", type=int, default=15, help="debridement trials of 8 picks per method, seed 0 (default: %(default)s)")
    parser.add_argument("--rate-steps", type=int, default=400, help="env steps per GridTouch throughput measurement (default: %(default)s)")
    parser.add_argument(
        "--pick-rate-steps", type=int, default=150, help="picks per pick-agent throughput measurement (default: %(default)s)"
    )
    parser.add_argument("--timing-trials", type=int, default=2, help="trials per resolution for the pick wall time (default: %(default)s)")
    parser.add_argument("--skip-rates", action="store_true", help="skip the throughput and pick-time measurements")
    parser.add_argument("--skip-comparison", action="store_true", help="only measure training throughput")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if not args.skip_rates and args.agents:
        throughput(args.rate_steps, args.pick_rate_steps, args.agents)
    if not args.skip_comparison:
        steps = resolve_budget(args.budget, args.steps)
        comparison(args, steps, resolve_budget(args.budget, args.pick_steps))


if __name__ == "__main__":
    main()
