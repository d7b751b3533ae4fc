"""What-ifs of the Phase I collector against the authors' real rows: the pause step and the heights.

The simulated Phase I follows the authors' collector (``scripts/automatic_trajectory_collector.py``
of :data:`dvrk_gym.paper.AUTHORS_CODE`): each trajectory runs straight from a corner 5 mm over
the paper towards a random target 1 mm over it, pausing every 2 mm
(:data:`dvrk_gym.paper.PHASE1_STEP_M`, :data:`dvrk_gym.envs.exploration.CORNER_Z_M` and
``TARGET_Z_M``). This measures it changed, a change for the measurement and not an option of
the package: ``--step-mm`` sets the pause step, ``--corner-mm`` and ``--target-mm`` the heights
of the corners and the targets over where the robot reports its jaws pushed onto the paper
(taken from one GridTouch-v0 push at the grid's middle, yaw 0, on the instrument measured;
the package takes instrument 0's, :data:`dvrk_gym.envs.exploration.PAPER_REPORTED_Z_M`, for
every instrument). The collector the simulator had before paused every millimetre, from
corners 2.6 mm over the paper towards targets spread over a 6 mm band around that height:
``--step-mm 1 --corner-mm 2.6 --target-mm 2.6`` is the nearest. The red-tape detector
searches only the authors' boxes of each image (:data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`);
``--no-search-box`` lets it search the whole image, as the simulator's did before, and
``--miss-probability`` sets its misses per image (29.0% matched the real share of kept rows
without the boxes). It prints the fidelity
comparison of ``dvrk-gym fidelity`` for that collection, the share of its kept rows whose
tape lay outside the boxes, and with ``--calibrate`` also the
calibration table of a whole calibration run with it (in a temporary folder, or ``--out``,
where ``benchmarks/fidelity_table_runs.py --calibration`` can read it; 4 minutes more at the
paper's budgets).

    python benchmarks/fidelity_collector.py --step-mm 1 --corner-mm 2.6 --target-mm 2.6 [--calibrate]
    python benchmarks/fidelity_collector.py --no-search-box --miss-probability 0.29 [--calibrate]
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
from fidelity_table_runs import marker_noise_replaced

from dvrk_gym import paper
from dvrk_gym.calibration import phase1
from dvrk_gym.calibration.benchmark import format_table as format_calibration_table
from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
from dvrk_gym.envs import exploration
from dvrk_gym.envs.grid_touch import HOME_POSITION_M
from dvrk_gym.fidelity.comparison import run_fidelity
from dvrk_gym.fidelity.instrument_model import pixels_of_camera_points
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
        if corner_z_m is not None:
            patches.enter_context(mock.patch.object(exploration, "CORNER_Z_M", corner_z_m))
        if target_z_m is not None:
            patches.enter_context(mock.patch.object(phase1, "TARGET_Z_M", target_z_m))
        patches.enter_context(mock.patch.object(phase1, "PaperExplorationPolicy", Stepped))
        yield


@contextlib.contextmanager
def detector(search_boxes: bool, miss_probability: float | None) -> Iterator[None]:
    """While open, every new simulated world's red-tape detector searches the whole image
    (``search_boxes`` False) instead of the authors' boxes, and misses each image with
    ``miss_probability`` (None keeps the identified one). Undone on exit."""
    if miss_probability is not None and not 0.0 <= miss_probability < 1.0:
        raise ValueError(f"miss_probability must be in [0, 1), got {miss_probability}")
    changes: dict[str, object] = {} if search_boxes else {"search_boxes_px": None}
    if miss_probability is not None:
        changes["miss_probability"] = miss_probability
    with marker_noise_replaced(**changes):
        yield


def outside_boxes_share(X: np.ndarray) -> float:
    """The share of rows (camera position (m) and angles, as the authors triangulated them)
    whose detections lie outside the authors' search boxes (:data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`):
    the left one by its (u, v), the right one by u minus the disparity (within a pixel; its
    row, known only to within the row mismatch, is not checked)."""
    u, v, disparity = pixels_of_camera_points(np.asarray(X, dtype=float)[:, :3]).T
    (lu, lv, lw, lh), (ru, _, rw, _) = paper.MARKER_SEARCH_BOXES_PX
    right_u = u - disparity
    inside = (lu < u) & (u < lu + lw) & (lv < v) & (v < lv + lh) & (ru < right_u) & (right_u < ru + rw)
    return float(1.0 - np.mean(inside))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--step-mm", type=float, default=1e3 * paper.PHASE1_STEP_M, help="pause step, mm (the authors' code and the simulator: 2)"
    )
    parser.add_argument(
        "--corner-mm",
        type=float,
        default=None,
        help="corners' height over the pushed jaws, mm (default: the simulator's, 5 over its paper)",
    )
    parser.add_argument(
        "--target-mm",
        type=float,
        default=None,
        help="targets' height over the pushed jaws, mm (default: the simulator's, 1 over its paper)",
    )
    parser.add_argument("--bias-seed", type=int, default=0, help="which instrument (default: 0)")
    parser.add_argument("--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="Phase I trajectories (default: 57)")
    parser.add_argument("--resolution", type=int, nargs=2, default=list(paper.ENDOSCOPE_RESOLUTION_PX), metavar=("W", "H"))
    parser.add_argument("--no-search-box", action="store_true", help="the tape detector searches the whole image, not the authors' boxes")
    parser.add_argument(
        "--miss-probability", type=float, default=None, help="the tape detector's misses per image (default: the identified ones)"
    )
    parser.add_argument("--calibrate", action="store_true", help="also run a whole calibration with it and print its table")
    parser.add_argument(
        "--out", type=Path, default=None, help="with --calibrate: keep its calibration folder here (default: a temporary folder)"
    )
    args = parser.parse_args()
    for name in ("corner_mm", "target_mm"):
        value = getattr(args, name)
        if value is not None and not (np.isfinite(value) and -2.0 <= value <= 20.0):
            parser.error(f"--{name.replace('_', '-')} must be in [-2, 20] mm, got {value}")
    if not (np.isfinite(args.step_mm) and 0.0 < args.step_mm <= 10.0):
        parser.error(f"--step-mm must be in (0, 10] mm, got {args.step_mm}")
    if args.miss_probability is not None and not 0.0 <= args.miss_probability < 1.0:
        parser.error(f"--miss-probability must be in [0, 1), got {args.miss_probability}")
    if args.out is not None and not args.calibrate:
        parser.error("--out keeps the folder of --calibrate's run: give --calibrate too")
    if args.out is not None and args.out.exists() and any(args.out.iterdir()):
        parser.error(f"--out {args.out} is not empty: a calibration run resumes what it finds there, made with other settings")
    resolution = (int(args.resolution[0]), int(args.resolution[1]))
    paper_z = pushed_jaws_height(args.bias_seed, resolution)
    corner = None if args.corner_mm is None else paper_z + 1e-3 * args.corner_mm
    target = None if args.target_mm is None else paper_z + 1e-3 * args.target_mm
    heights = f"corners {args.corner_mm}, targets {args.target_mm} mm over it (None: the simulator's)"
    print(f"the jaws pushed onto the paper report {1e3 * paper_z:.1f} mm; step {args.step_mm:g} mm, {heights}")
    searched = "the whole image" if args.no_search_box else "the authors' boxes"
    misses = "as identified" if args.miss_probability is None else f"{args.miss_probability:g} of the images"
    print(f"the tape detector searches {searched} and misses {misses}")
    with (
        collector(1e-3 * args.step_mm, corner, target),
        detector(search_boxes=not args.no_search_box, miss_probability=args.miss_probability),
    ):
        run = run_fidelity(bias_seed=args.bias_seed, n_trajectories=args.trajectories, camera_resolution=resolution, progress=False)
        print(format_fidelity_table(run))
        outside = f"real {outside_boxes_share(run.real_X):.3f}, simulated {outside_boxes_share(run.sim_X):.3f}"
        print(f"kept rows outside the authors' search boxes: {outside}")
        if args.calibrate:
            config = PipelineConfig(n_trajectories=args.trajectories, bias_seed=args.bias_seed, camera_resolution=resolution)
            with contextlib.ExitStack() as stack:
                folder = args.out if args.out is not None else Path(stack.enter_context(tempfile.TemporaryDirectory()))
                result = run_calibration(folder, config, progress=False, benchmark=True)
            print(format_calibration_table(result["table"]))
