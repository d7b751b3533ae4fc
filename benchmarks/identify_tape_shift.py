"""Identify the red-tape detector's right-image shift from the records of the paper's table.

The real Phase I rows put the tape 0.953 times as far from the lens as it was
(:data:`dvrk_gym.sim.identified.CAMERA`), and they cannot say why: a stereo calibration
whose baseline is short sees everything nearer, a tape detector whose right-image centroid
lies left of the tape sees the tape alone nearer, and the rows hold only the tape. The
records of the table's runs can (:func:`dvrk_gym.calibration.datasets.load_paper_table_runs`):
the rigid body fitted to the tape's rows was asked where the printed circles were, and put
them 5.5 to 8.4 mm under the jaws pushed onto those circles (mean -7.2 mm over the five
yaws). Seen nearer than the circles, the tape teaches a mapping that sends the circles deeper.

For each candidate shift (``--shifts``; the true baseline follows from it so that the tape
stays where the rows put it, :func:`dvrk_gym.sim.endoscope.baseline.true_baseline_m`) this
collects the paper's Phase I on the instrument, fits the rigid body to its kept rows,
touches the 35 circles at the table's six settings with ``dvrk-gym evaluate``'s seeds,
its predictions unlifted, and prints
the statistics of ``benchmarks/fidelity_table_runs.py``: the prediction's median height over
the plane through the simulated pushes at each yaw, and the table's error. The identified
shift is where the mean height over the five yaws crosses the real one (linear between the
two candidates around it). Then the same on instruments it was not identified on
(``--check-seeds``), at the identified shift. The network is not fitted: the rigid body is
the linear map that shows the shift; a network trained on the same rows stays near the
rows' heights (``fidelity_table_runs.py``).

About 1 minute per candidate and instrument on a quiet core:

    python benchmarks/identify_tape_shift.py [--shifts 0 2 3 4] [--bias-seed 0] [--check-seeds 1 2 3]
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
from fidelity_table_runs import FIXED_YAWS, marker_noise_replaced, real_table, simulated_table

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_table_runs
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.phase1 import run_paper_phase1
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.evaluation.table_protocol import RAW
from dvrk_gym.sim import identified
from dvrk_gym.sim.endoscope.baseline import true_baseline_m
from dvrk_gym.sim.endoscope.noise import MAX_RIGHT_SHIFT_PX

UNLIFTED = (RAW,) * len(paper.CALIBRATION_SETTINGS)
"""No band and no lift at any setting: the predictions sent as they are (``dvrk-gym evaluate
--protocol raw``); the dive is measured on the predictions, whatever lifts them."""


@contextlib.contextmanager
def tape_shift(pixels: float) -> Iterator[None]:
    """While open, every new simulated world's red-tape detector has the right-image shift
    ``pixels`` (px at 1080p) instead of the identified one, and its endoscope the true
    baseline that goes with it. Undone on exit. (Nested, the outer shift wins.)"""
    with marker_noise_replaced(right_shift_px=pixels):
        yield


def rigid_body_rows(shift_px: float, bias_seed: int, seed: int) -> list[tuple[float, ...]]:
    """Per setting of the table, the statistics of ``fidelity_table_runs.statistics`` for the rigid
    body of instrument ``bias_seed`` collected with the tape shift ``shift_px``, touched unlifted."""
    with tape_shift(shift_px):
        phase1 = run_paper_phase1(seed=seed, bias_seed=bias_seed, progress=False)
        clean = phase1.cleaned()
        policy = CalibratedPolicy(RigidBodyCalibrator().fit(clean.X, clean.y))
        env = gym.make("dvrk_gym/GridTouch-v0", bias="paper", bias_seed=bias_seed)
        try:
            return simulated_table(env, policy, UNLIFTED)
        finally:
            env.close()


def mean_height_mm(rows: list[tuple[float, ...]]) -> float:
    """The mean over the five fixed yaws of the prediction's median height over the pushed jaws, mm."""
    return float(np.mean([row[1] for row in rows[:FIXED_YAWS]]))


def crossing(shifts: np.ndarray, heights: np.ndarray, target: float) -> float:
    """The shift (px) where the heights (mm), linear between neighbouring candidates sorted by
    shift, first reach ``target`` (mm); ValueError if no two neighbours bracket it."""
    order = np.argsort(shifts)
    x, y = shifts[order], heights[order]
    for i in range(len(x) - 1):
        if (y[i] - target) * (y[i + 1] - target) <= 0.0 and y[i] != y[i + 1]:
            return float(x[i] + (target - y[i]) * (x[i + 1] - x[i]) / (y[i + 1] - y[i]))
    raise ValueError(f"no two candidate shifts bracket {target:.2f} mm (heights {np.round(heights, 2).tolist()} mm); widen --shifts")


def print_row(name: str, rows: list[tuple[float, ...]]) -> None:
    heights = "".join(f"{row[1]:>8.1f}" for row in rows[:FIXED_YAWS])
    errors = np.array([row[0] for row in rows])
    print(f"  {name:<34s}{heights}{mean_height_mm(rows):>8.1f}   error {errors.mean():5.1f} px")


def main(shifts: list[float], bias_seed: int, check_seeds: list[int], seed: int) -> None:
    real = real_table(load_paper_table_runs())["RBT"]
    target = mean_height_mm(real)
    print("the rigid body's prediction over the pushed jaws, mm, median per yaw (-90 .. 90), their mean; and the table's error")
    print(f"  {'':<34s}" + "".join(f"{d:>8.0f}" for d in paper.PHASE2_YAWS_DEG) + f"{'mean':>8s}")
    print_row("real (the table's runs)", real)
    heights = []
    for shift in shifts:
        rows = rigid_body_rows(shift, bias_seed, seed)
        heights.append(mean_height_mm(rows))
        print_row(f"sim {bias_seed}, shift {shift:g} px (B {1e3 * true_baseline_m(shift):.3f} mm)", rows)
    identified_shift = crossing(np.array(shifts), np.array(heights), target)
    print(
        f"identified: right-image shift {identified_shift:.2f} px (the height's mean reaches the real {target:.1f} mm); "
        f"true baseline {1e3 * true_baseline_m(identified_shift):.3f} mm against the authors' "
        f"{1e3 * paper.ENDOSCOPE_BASELINE_M:.3f} mm; the package's: {identified.TAPE_RIGHT_SHIFT_PX:g} px"
    )
    for other in check_seeds:
        print_row(f"sim {other} (not identified on), {identified_shift:.2f} px", rigid_body_rows(identified_shift, other, seed))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shifts", type=float, nargs="+", default=[0.0, 2.0, 3.0, 4.0], help="candidate shifts, px at 1080p")
    parser.add_argument("--bias-seed", type=int, default=0, help="the instrument identified on")
    parser.add_argument("--check-seeds", type=int, nargs="*", default=[1, 2, 3], help="instruments to check the shift on")
    parser.add_argument("--seed", type=int, default=0, help="seeds the Phase I collection")
    args = parser.parse_args()
    if len(set(args.shifts)) < 2 or not all(np.isfinite(s) and abs(s) <= MAX_RIGHT_SHIFT_PX for s in args.shifts):
        parser.error(f"--shifts needs at least two distinct values in [-{MAX_RIGHT_SHIFT_PX:g}, {MAX_RIGHT_SHIFT_PX:g}] px")
    if min([args.bias_seed, *args.check_seeds]) < 0 or args.seed < 0:
        parser.error("--bias-seed, --check-seeds and --seed must be >= 0")
    main(args.shifts, args.bias_seed, args.check_seeds, args.seed)
