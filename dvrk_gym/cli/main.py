"""The ``dvrk-gym`` command line."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Callable, Sequence

from dvrk_gym.cli.baselines import add_commands as add_baseline_commands
from dvrk_gym.cli.calibration import add_commands as add_calibration_commands
from dvrk_gym.cli.debridement import add_commands as add_debridement_commands
from dvrk_gym.cli.options import add_instrument_options
from dvrk_gym.cli.reproduce import add_commands as add_reproduce_commands

Command = Callable[[argparse.Namespace], int]


def _add_demo(subparsers: argparse._SubParsersAction) -> None:
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
    parser.add_argument("--circles", type=int, default=7, help="how many grid circles to touch, 1-35 (default: %(default)s)")
    parser.set_defaults(func=_run_demo)


def _run_demo(args: argparse.Namespace) -> int:
    from dvrk_gym.demo import run_demo

    return run_demo(args.out, bias=args.bias, bias_seed=args.bias_seed, resolution=tuple(args.resolution), n_circles=args.circles)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``dvrk-gym`` command."""
    parser = argparse.ArgumentParser(
        prog="dvrk-gym",
        description="Simulated dVRK calibration and debridement (Seita et al., ICRA 2018).",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_reproduce_commands(subparsers)
    _add_demo(subparsers)
    add_calibration_commands(subparsers)
    add_debridement_commands(subparsers)
    add_baseline_commands(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dvrk-gym`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except (ValueError, FileNotFoundError) as error:
        print(f"dvrk-gym {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dvrk-gym {args.command}: interrupted (cached stages are kept: the same command resumes)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
