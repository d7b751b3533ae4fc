"""What-ifs of the Phase I collector against the authors' real rows: the pause step and the heights.

The authors' collector (``scripts/automatic_trajectory_collector.py`` of
:data:`dvrk_gym.paper.AUTHORS_CODE`) drove each trajectory along one straight path from a
corner 5 mm over the paper to a random target 1 mm over it, pausing every 20 steps of 0.1 mm
(2 mm). The simulated collection pauses every :data:`dvrk_gym.paper.PHASE1_STEP_M` (1 mm),
93 poses a trajectory, from corners at the middle of a 6 mm band of heights towards targets
anywhere in it. This measures the simulated collection changed that way, a change for the
measurement and not an option of the package: ``--step-mm`` sets the pause step,
``--corner-mm`` and ``--target-mm`` the heights of the corners and the targets over where the
robot reports its jaws pushed onto the paper (taken from one GridTouch-v0 push at the grid's
middle, yaw 0). It prints the fidelity comparison of ``dvrk-gym fidelity`` for that
collection, and with ``--calibrate`` also the calibration table of a whole calibration run
with it (in a temporary folder; 4 minutes more at the paper's budgets).

    python benchmarks/fidelity_collector.py --step-mm 2 --corner-mm 5 --target-mm 1 [--calibrate]
"""

from __future__ import annotations

import argparse
import contextlib
import tempfile
from collections.abc import Iterator
from pathlib import Path
from unittest import mock

import gymnasium as gym
import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration import phase1
from dvrk_gym.calibration.benchmark import format_table as format_calibration_table
from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
from dvrk_gym.envs import exploration
from dvrk_gym.envs.grid_touch import HOME_POSITION_M
from dvrk_gym.fidelity.comparison import run_fidelity
from dvrk_gym.fidelity.report import format_table as format_fidelity_table


def pushed_jaws_height(bias_seed: int, resolution: tuple[int, int]) -> float:
    """Where the simulated robot reports its jaws pushed onto the paper at the grid's middle and
    yaw 0: the reported height after GridTouch-v0's simulated person's push, metres."""
    env = gym.make("dvrk_gym/GridTouch-v0", bias="paper", bias_seed=bias_seed, camera_resolution=resolution)
    try:
        env.reset(seed=0, options={"yaw": 0.0, "circle": 17})
        _, _, _, _, info = env.step(np.array([*HOME_POSITION_M[:2], HOME_POSITION_M[2] - 0.03, 0.0], dtype=np.float32))
        return float(info["reported_position"][2] + info["human_correction"][2])
    finally:
        env.close()


@contextlib.contextmanager
def collector(step_m: float, corner_z_m: float | None, target_z_m: float | None) -> Iterator[None]:
    """While open, Phase I collections pause every ``step_m`` metres, start at corners at the
    height ``corner_z_m`` and head for targets at ``target_z_m`` (base frame, metres; None keeps
    the simulator's). Undone on exit."""
    if not (np.isfinite(step_m) and 0.0 < step_m <= 0.01):
        raise ValueError(f"step_m must be in (0, 0.01] m, got {step_m}")
    original = phase1.PaperExplorationPolicy

    class Stepped(original):  # type: ignore[misc, valid-type]
        def __init__(
            self, seed: int | None = None, step_m: float = step_m, rotations_per_pause: int = paper.PHASE1_ROTATIONS_PER_PAUSE
        ) -> None:
            super().__init__(seed=seed, step_m=step_m, rotations_per_pause=rotations_per_pause)

    with contextlib.ExitStack() as patches:
        if corner_z_m is not None:  # the corners sit at the middle of this band
            patches.enter_context(mock.patch.object(exploration, "SAFE_Z_M", (corner_z_m, corner_z_m)))
        if target_z_m is not None:
            patches.enter_context(mock.patch.object(phase1, "SAFE_Z_M", (target_z_m, target_z_m)))
        patches.enter_context(mock.patch.object(phase1, "PaperExplorationPolicy", Stepped))
        yield


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--step-mm", type=float, default=1e3 * paper.PHASE1_STEP_M, help="pause step, mm (the simulator: 1; the authors' code: 2)"
    )
    parser.add_argument("--corner-mm", type=float, default=None, help="corners' height over the pushed jaws, mm (the authors: 5)")
    parser.add_argument("--target-mm", type=float, default=None, help="targets' height over the pushed jaws, mm (the authors: 1)")
    parser.add_argument("--bias-seed", type=int, default=0, help="which instrument (default: 0)")
    parser.add_argument("--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="Phase I trajectories (default: 57)")
    parser.add_argument("--resolution", type=int, nargs=2, default=list(paper.ENDOSCOPE_RESOLUTION_PX), metavar=("W", "H"))
    parser.add_argument("--calibrate", action="store_true", help="also run a whole calibration with it and print its table")
    args = parser.parse_args()
    for name in ("corner_mm", "target_mm"):
        value = getattr(args, name)
        if value is not None and not (np.isfinite(value) and -2.0 <= value <= 20.0):
            parser.error(f"--{name.replace('_', '-')} must be in [-2, 20] mm, got {value}")
    if not (np.isfinite(args.step_mm) and 0.0 < args.step_mm <= 10.0):
        parser.error(f"--step-mm must be in (0, 10] mm, got {args.step_mm}")
    resolution = (int(args.resolution[0]), int(args.resolution[1]))
    paper_z = pushed_jaws_height(args.bias_seed, resolution)
    corner = None if args.corner_mm is None else paper_z + 1e-3 * args.corner_mm
    target = None if args.target_mm is None else paper_z + 1e-3 * args.target_mm
    heights = f"corners {args.corner_mm}, targets {args.target_mm} mm over it (None: the simulator's)"
    print(f"the jaws pushed onto the paper report {1e3 * paper_z:.1f} mm; step {args.step_mm:g} mm, {heights}")
    with collector(1e-3 * args.step_mm, corner, target):
        run = run_fidelity(bias_seed=args.bias_seed, n_trajectories=args.trajectories, camera_resolution=resolution, progress=False)
        print(format_fidelity_table(run))
        if args.calibrate:
            config = PipelineConfig(n_trajectories=args.trajectories, bias_seed=args.bias_seed, camera_resolution=resolution)
            with tempfile.TemporaryDirectory() as folder:
                result = run_calibration(Path(folder), config, progress=False, benchmark=True)
            print(format_calibration_table(result["table"]))
