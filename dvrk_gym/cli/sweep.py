"""``dvrk-gym sweep``: the paper's calibration over instruments x calibrators x seeds, locally or on Dask."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dvrk_gym import paper
from dvrk_gym.cli.options import add_executor_options, add_progress_option, add_resolution_option, make_executor, writable_folder


def _run_sweep(args: argparse.Namespace) -> int:
    from dvrk_gym.calibration.pipeline import PipelineConfig
    from dvrk_gym.sweep import SweepError, SweepSettings, format_rows, parse_calibrators, parse_int_list, run_sweep

    settings = SweepSettings(
        bias_seeds=parse_int_list(args.bias_seeds, "--bias-seeds"),
        calibrators=parse_calibrators(args.calibrators),
        seeds=parse_int_list(args.seeds, "--seeds"),
        pipeline=PipelineConfig(
            n_trajectories=args.trajectories, dnn_epochs=args.epochs, bias=args.bias, camera_resolution=tuple(args.resolution)
        ),
    )
    writable_folder(args.out)  # before the grid is announced: an --out that cannot hold it is refused first
    executor = make_executor(args)
    units = len(settings.units())
    print(f"sweep: {len(settings.bias_seeds)} instruments x {len(settings.seeds)} seeds = {units} units on {executor.description}")
    try:
        with executor:
            result = run_sweep(settings, args.out, executor, progress=not args.no_progress)
    except SweepError as error:
        print(f"dvrk-gym sweep: {error}", file=sys.stderr)
        return 1
    print(format_rows(result.rows))
    print(f"\n{len(result.computed)} units run, {len(result.loaded)} loaded from {args.out}; {result.wall_s:.0f} s")
    print(f"wrote {result.csv} ({len(result.rows)} rows) and {result.figure}")
    return 0


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``sweep``."""
    parser = subparsers.add_parser(
        "sweep",
        help="the calibration table over a grid of instruments, calibrators and seeds (local processes or a Dask cluster)",
        description="Runs the paper's two-phase calibration once per instrument and seed (a unit) and benchmarks "
        "its calibrators on the 35 circles in the six settings. Writes sweep.csv (one row per instrument, "
        "calibrator and seed), sweep_errors.png (error per instrument) and units/<unit>.json into --out. Each "
        "unit is kept as it finishes: the same command resumes, and a larger grid reuses the finished units. "
        "The budget defaults to the paper's (a minute or more a unit on one core); --trajectories 3 --epochs 20 "
        "--resolution 640 360 makes a unit take seconds.",
    )
    parser.add_argument("--bias-seeds", default="0-4", help="instruments: numbers and ranges, e.g. 0-4 or 0,3,7-9 (default: %(default)s)")
    parser.add_argument("--calibrators", default="rbt,dnn,dnn+rf", help="calibrators in the table (default: %(default)s)")
    parser.add_argument("--seeds", default="0", help="run seeds: numbers and ranges (default: %(default)s)")
    add_executor_options(parser, "units")
    parser.add_argument("--out", type=Path, default=Path("dvrk_gym_out/sweep"), help="output folder (default: %(default)s)")
    parser.add_argument("--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="Phase I trajectories (the paper: %(default)s)")
    parser.add_argument("--epochs", type=int, default=paper.DNN_EPOCHS, help="DNN training epochs (the paper: %(default)s)")
    add_resolution_option(parser)
    parser.add_argument("--bias", default="paper", help="cable bias preset: none, paper or severe (default: %(default)s)")
    add_progress_option(parser)
    parser.set_defaults(func=_run_sweep)
