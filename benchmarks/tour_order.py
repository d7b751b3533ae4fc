"""What the order of the touches does: the authors' tour against the grid's row-major order.

The cables keep their history from one touch to the next, so the order the circles are
touched in is part of the protocol. The authors toured theirs row by row along the robot's
+y, each row from +x to -x (:data:`dvrk_gym.envs.grid_touch.TOUR`, from their records); the
package toured each row from -x to +x until it took theirs. For a calibration run, this
script prints:

1. the calibration table's mean error per method and setting (mm), touched as ``dvrk-gym
   evaluate`` does (its seeds, from the run's seed, and its protocol: the rigid body's
   heights lifted as the authors' runs did; each pass starts relaxed and carries the
   history within it), in the authors' order and in row-major order. The forests learned
   their corrections from the run's Phase II, which toured the authors' order;
2. how the Phase II pushes (how far a person moved the jaws from the network's prediction
   onto the circle) depend on the move before them, real and simulated: their mean x and y
   (mm, the robot's frame) after a move along a row (towards -x) and after the move to the
   next row (back towards +x), per yaw, and the difference in x between the two. Play in
   the joints would leave the jaws short of each move, on the side they came from (a
   positive difference); the simulated cables give a small positive one, the real robot's
   pushes a negative one.

About 1 minute after the calibration:

    dvrk-gym calibrate --out runs/cal
    python benchmarks/tour_order.py --calibration runs/cal
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from fidelity_table_runs import add_calibration_argument, read_calibration, real_pushes, simulated_pushes

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym import paper
from dvrk_gym.calibration.benchmark import YAW_SETTINGS, touch_grid_episodes
from dvrk_gym.calibration.datasets import PaperTableRuns, load_paper_table_runs
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.models.features import nearest_yaw_index
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.calibration.pipeline import BENCHMARK_SEED_OFFSET, PipelineConfig
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.envs.grid_touch import N_CIRCLES, TOUR
from dvrk_gym.evaluation.table_protocol import RuledPolicy, paper_rules

ORDERS: dict[str, tuple[int, ...]] = {"authors'": TOUR, "row-major": tuple(range(N_CIRCLES))}
"""The two orders the table is touched in, as circle indices."""
ROW_MOVE_M = 0.005
"""A move between successive pushes whose +x exceeds this goes to the next row, metres (the
moves along a row go 10 to 17 mm towards -x; to the next row, 30 to 70 mm back)."""


def mean_error(env: gym.Env, policy: Any, setting: int, order: tuple[int, ...], seed: int) -> float:
    """Mean touch error (mm) of one pass over the circles in ``order`` at ``setting`` of
    YAW_SETTINGS, its first reset seeded with ``seed + setting`` (as ``calibration_table`` seeds it)."""
    episodes = touch_grid_episodes(env, policy, YAW_SETTINGS[setting][1], seed=seed + setting, order=order)
    return float(np.mean([e.metrics["mm_error"] for e in episodes]))


def pushes_by_move(sent: np.ndarray, pushes: np.ndarray, yaws: np.ndarray) -> np.ndarray:
    """Per paper yaw, the mean push (x, y) after a move along a row and after a move to the next
    row, (5, 2, 2) m: ``sent`` (n, 3) m where each touch was sent, in the order touched;
    ``pushes`` (n, 3) m; ``yaws`` (n,) rad. A move to the next row goes more than
    :data:`ROW_MOVE_M` towards +x (the authors' tour); the first touch of each yaw has no move
    before it. NaN where a yaw has no such move. Raises ValueError if the lengths differ."""
    if not len(sent) == len(pushes) == len(yaws):
        raise ValueError(f"sent, pushes and yaws must be as long, got {len(sent)}, {len(pushes)}, {len(yaws)}")
    nearest = nearest_yaw_index(yaws)
    out = np.full((len(paper.PHASE2_YAWS_DEG), 2, 2), np.nan)
    for k in range(len(paper.PHASE2_YAWS_DEG)):
        rows = np.flatnonzero(nearest == k)
        if len(rows) < 2:
            continue
        moves = np.diff(sent[rows], axis=0)
        after = pushes[rows[1:], :2]
        next_row = moves[:, 0] > ROW_MOVE_M
        for j, chosen in enumerate((~next_row, next_row)):
            if chosen.any():
                out[k, j] = after[chosen].mean(axis=0)
    return out


def print_orders(calibration_folder: Path, config: PipelineConfig, phase2: Phase2Data) -> None:
    """Part 1: each calibrator's mean error per setting, touched in each of :data:`ORDERS` by the
    paper's protocol (the authors' band carried over by ``phase2``'s pushes)."""
    print("1. Mean touch error (mm) per setting, touched in each order")
    print(f"  {'method':<8s}{'order':<11s}" + "".join(f"{label:>9s}" for label, _ in YAW_SETTINGS) + f"{'mean':>9s}")
    env = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
    try:
        for name, label in paper.METHOD_LABELS.items():
            policy = CalibratedPolicy(load_calibrator(calibration_folder, name)[0])
            rules = paper_rules(label, phase2.corrected[:, 2])
            for order_name, order in ORDERS.items():
                cells = [
                    mean_error(env, RuledPolicy(policy, rules[k]), k, order, config.seed + BENCHMARK_SEED_OFFSET)
                    for k in range(len(YAW_SETTINGS))
                ]
                print(f"  {label:<8s}{order_name:<11s}" + "".join(f"{v:9.2f}" for v in cells) + f"{np.mean(cells):9.2f}")
    finally:
        env.close()


def next_row_gap(by_move: np.ndarray) -> float:
    """The x after the move to the next row minus after a move along a row, the mean over the yaws
    that have both, of :func:`pushes_by_move`'s (5, 2, 2) means (in their unit)."""
    return float(np.nanmean(by_move[:, 1, 0] - by_move[:, 0, 0]))


def print_pushes_by_move(runs: PaperTableRuns, phase2: Phase2Data) -> None:
    """Part 2: the pushes after each kind of move (:func:`pushes_by_move`), real (both rounds) and simulated."""
    print("2. Phase II pushes (x, y mm) after a move along a row | after the move to the next row, per yaw")
    robots = [(f"real, round {k}", real_pushes(runs, k)) for k in (0, 1)]
    robots.append(("sim", simulated_pushes(phase2)))
    for who, (sent, pushes, yaws) in robots:
        means = 1e3 * pushes_by_move(sent, pushes, yaws)
        cells = "   ".join(
            f"{yaw:+4.0f}: {a[0]:+.1f},{a[1]:+.1f} | {b[0]:+.1f},{b[1]:+.1f}"
            for yaw, (a, b) in zip(paper.PHASE2_YAWS_DEG, means, strict=True)
        )
        print(f"  {who:<14s}{cells}   x after the next-row move minus along a row: {next_row_gap(means):+.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_calibration_argument(parser)
    args = parser.parse_args()
    config = read_calibration(parser, args.calibration)
    phase2 = Phase2Data.load(args.calibration / "phase2.npz")
    if not phase2.in_authors_tour:
        parser.error(f"{args.calibration} holds a Phase II made before the authors' tour; make the calibration again")
    print_orders(args.calibration, config, phase2)
    print_pushes_by_move(load_paper_table_runs(), phase2)


if __name__ == "__main__":
    main()
