"""Environment throughput: GridTouch start-up and steps per second, and the paper's Phase I collection.

Run: python benchmarks/bench_envs.py  [--steps 500] [--trajectories 57] [--starts 4]
Targets (issue 4): at least 100 GridTouch steps/s on one core, and the paper's 57
exploration trajectories in under 90 s, both at the paper's 1920 x 1080 pixel density.
The start-up times (``gym.make`` and the first ``reset``) come first, in a process that has
made no env yet: the first env detects the printed grid in two full-frame renders, and
later envs of the same scene and camera read its detections
(:mod:`dvrk_gym.sim.endoscope.printed_grid`).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import dvrk_gym  # noqa: F401
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, collect_phase1
from dvrk_gym.cli.options import check_flag_bounds
from dvrk_gym.sim.endoscope import printed_grid


def start_times(n_envs: int) -> list[float]:
    """Seconds of ``gym.make`` plus the first ``reset`` of ``n_envs`` GridTouch-v0 envs in turn."""
    times = []
    for seed in range(n_envs):
        start = time.perf_counter()
        env = gym.make("dvrk_gym/GridTouch-v0", bias="paper")
        env.reset(seed=seed)
        times.append(time.perf_counter() - start)
        env.close()
    return times


def grid_touch_rate(n_steps: int) -> float:
    env = gym.make("dvrk_gym/GridTouch-v0", bias="paper")
    env.reset(seed=0)
    env.unwrapped.world.observe_grid()  # the one-off full-frame grid detection is not a step
    rng = np.random.default_rng(0)
    space = env.action_space
    actions = [rng.uniform(space.low, space.high).astype(np.float32) for _ in range(n_steps)]
    env.step(actions[0])  # the first step's one-off work (17-28 ms, 40-60 steps' worth) is not timed
    start = time.perf_counter()
    for action in actions:
        env.reset()
        env.step(action)
    elapsed = time.perf_counter() - start
    env.close()
    return n_steps / elapsed


def phase1_collection(n_trajectories: int) -> tuple[float, int, int]:
    env = gym.make("dvrk_gym/CalibrationExploration-v0", bias="paper")
    start = time.perf_counter()
    data = collect_phase1(env, PaperExplorationPolicy(seed=0), n_trajectories, progress=False)
    elapsed = time.perf_counter() - start
    env.close()
    return elapsed, data.n_raw, data.n_kept


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=500, help="GridTouch steps to time (default: %(default)s)")
    parser.add_argument("--trajectories", type=int, default=57, help="Phase I trajectories (default: %(default)s)")
    parser.add_argument("--starts", type=int, default=4, help="GridTouch envs made and reset in turn, at least 2 (default: %(default)s)")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"steps": (1, 10**7), "trajectories": (1, 10**4), "starts": (2, 1000)})
    starts = start_times(args.starts)
    rate = grid_touch_rate(args.steps)
    printed_grid.clear_cache()  # Phase I's figure includes its own world's grid detection, as before the cache
    elapsed, raw, kept = phase1_collection(args.trajectories)
    print(f"{'figure':<60} {'value':>12}")
    print(f"{'GridTouch-v0 make + first reset, first env of the process, s':<60} {starts[0]:>12.3f}")
    print(f"{'GridTouch-v0 make + first reset, later envs (median), s':<60} {float(np.median(starts[1:])):>12.3f}")
    print(f"{'GridTouch-v0 steps/s (one touch per step, 1920x1080)':<60} {rate:>12.1f}")
    print(f"{f'Phase I: {args.trajectories} trajectories, wall time s':<60} {elapsed:>12.1f}")
    print(f"{'Phase I: raw samples':<60} {raw:>12d}")
    print(f"{'Phase I: kept samples (both cameras, views agree)':<60} {kept:>12d}")
    print(f"{'Phase I: kept fraction (paper: 1939 / 5256 = 37%)':<60} {kept / raw:>12.1%}")


if __name__ == "__main__":
    main()
