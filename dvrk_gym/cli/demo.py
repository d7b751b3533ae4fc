"""``dvrk-gym demo``: touch grid circles with the uncalibrated robot and print what happens (:mod:`dvrk_gym.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dvrk_gym import paper
from dvrk_gym.cli.options import add_instrument_options, writable_folder


def _run_demo(args: argparse.Namespace) -> int:
    from dvrk_gym.demo import run_demo

    width, height = args.resolution
    writable_folder(args.out)
    result = run_demo(args.out, bias=args.bias, bias_seed=args.bias_seed, resolution=(width, height), n_circles=args.circles)
    print(f"endoscope {width}x{height}: {result.circles_found} of {paper.GRID_CIRCLES} grid circles found in both images")
    print(
        f"{'circle':>6} {'reported tip (mm)':>24} {'true tip (mm)':>24} {'miss mm':>8} {'miss px':>8}"
        "  marker seen (L/R)  marker camera xyz (mm)"
    )
    for touch in result.touches:
        marker = touch.marker
        seen = f"{'yes' if marker.seen_left else 'no':>3}/{'yes' if marker.seen_right else 'no':<3}"
        xyz = "-" if not marker.seen_both else np.array2string(1e3 * marker.camera_position, precision=1)
        print(
            f"{touch.circle:>6} {np.array2string(1e3 * touch.reported_tip_m, precision=1):>24} "
            f"{np.array2string(1e3 * touch.true_tip_m, precision=1):>24} {touch.miss_mm:>8.2f} {touch.miss_px:>8.1f}  {seen:>17}  {xyz}"
        )
    print(f"simulated robot time: {result.sim_time_s:.1f} s; images: {', '.join(str(p) for p in result.images.values())}")
    return 0


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``demo``."""
    parser = subparsers.add_parser(
        "demo",
        help="build the world, touch grid circles, save a stereo pair, print what the cameras saw",
        description=(
            "Builds the simulated dVRK workspace, moves the tool over the printed grid using the "
            "robot's own (nominal) kinematics, saves the endoscope's stereo pair as PNG and prints, "
            "for each circle touched, what the robot reported, where its jaws really were and what "
            "the cameras saw."
        ),
    )
    parser.add_argument("--out", type=Path, default=Path("dvrk_gym_out/demo"), help="output folder (default: %(default)s)")
    add_instrument_options(parser)
    parser.add_argument(
        "--circles", type=int, default=7, help=f"how many grid circles to touch, 1-{paper.GRID_CIRCLES} (default: %(default)s)"
    )
    parser.set_defaults(func=_run_demo)
