"""Environment throughput: GridTouch steps per second and the paper's Phase I collection.

Run: python benchmarks/bench_envs.py  [--trajectories 57]
Targets (issue 4): at least 100 GridTouch steps/s on one core, and the paper's 57
exploration trajectories in under 90 s, both at the paper's 1920 x 1080 pixel density.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import dvrk_gym  # noqa: F401
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, collect_phase1


def grid_touch_rate(n_steps: int) -> float:
    env = gym.make("dvrk_gym/GridTouch-v0", bias="paper")
    env.reset(seed=0)
    env.unwrapped.world.observe_grid()  # the one-off full-frame grid detection is not a step
    rng = np.random.default_rng(0)
    space = env.action_space
    actions = [rng.uniform(space.low, space.high).astype(np.float32) for _ in range(n_steps)]
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
    args = parser.parse_args()
    rate = grid_touch_rate(args.steps)
    elapsed, raw, kept = phase1_collection(args.trajectories)
    print(f"{'figure':<60} {'value':>12}")
    print(f"{'GridTouch-v0 steps/s (one touch per step, 1920x1080)':<60} {rate:>12.1f}")
    print(f"{f'Phase I: {args.trajectories} trajectories, wall time s':<60} {elapsed:>12.1f}")
    print(f"{'Phase I: raw samples':<60} {raw:>12d}")
    print(f"{'Phase I: kept samples (both cameras, views agree)':<60} {kept:>12d}")
    print(f"{'Phase I: kept fraction (paper: 1939 / 5256 = 37%)':<60} {kept / raw:>12.1%}")


if __name__ == "__main__":
    main()
