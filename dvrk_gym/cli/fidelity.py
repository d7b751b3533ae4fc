"""``dvrk-gym fidelity``: a simulated Phase I against the authors' real rows, statistic by statistic."""

from __future__ import annotations

import argparse
from pathlib import Path

from dvrk_gym import paper
from dvrk_gym.cli.options import add_instrument_options, add_progress_option, writable_folder


def _run_fidelity(args: argparse.Namespace) -> int:
    from dvrk_gym.fidelity.comparison import run_fidelity
    from dvrk_gym.fidelity.report import format_table, write_report
    from dvrk_gym.fidelity.uncertainty import MAX_BOOTSTRAP_REPLICATES

    if args.bootstrap != 0 and not (isinstance(args.bootstrap, int) and 2 <= args.bootstrap <= MAX_BOOTSTRAP_REPLICATES):
        raise ValueError(f"--bootstrap must be 0 (no standard errors) or an int in [2, {MAX_BOOTSTRAP_REPLICATES}], got {args.bootstrap}")
    writable_folder(args.out)  # before the collection: a folder that cannot hold the report is found now
    run = run_fidelity(
        bias=args.bias,
        bias_seed=args.bias_seed,
        wrist_settle_lag=args.wrist_settle_lag,
        n_trajectories=args.trajectories,
        seed=args.seed,
        camera_resolution=tuple(args.resolution),
        progress=not args.no_progress,
        bootstrap_replicates=args.bootstrap,
    )
    print(format_table(run))
    json_path, png_path = write_report(run, args.out)
    print(f"wrote {json_path}, {png_path}")
    return 0


def _settle_lag(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1), got {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1), got {value}")
    return value


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register fidelity."""
    fidelity = subparsers.add_parser(
        "fidelity",
        help="how close the simulated robot is to the real one: Phase I statistics side by side with the authors' rows",
        description="Collect Phase I in simulation for an instrument (--bias, --bias-seed) and print, side by side with "
        "the authors' 1939 real rows, the statistics that tell them apart (rigid residual and its direction, "
        "sample-to-sample jitter, kept rows per yaw and their pitches, the tilt of their plane, contiguous 10-fold CV), "
        "each against its target; write fidelity.json and fidelity.png to --out.",
    )
    fidelity.add_argument("--out", type=Path, default=Path("dvrk_gym_out/fidelity"), help="output folder (default: %(default)s)")
    fidelity.add_argument(
        "--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="simulated Phase I trajectories (the paper: %(default)s)"
    )
    fidelity.add_argument("--seed", type=int, default=0, help="seeds the exploration and the forest (default: %(default)s)")
    add_instrument_options(fidelity)
    fidelity.add_argument(
        "--wrist-settle-lag",
        type=_settle_lag,
        default=None,
        metavar="FRACTION",
        help="the preset with wrist motors that stop this fraction of each step short, in [0, 1), instead of its "
        "own: the reported pose lags the command (default: the preset's; paper's is 0.19, matched to the real rows)",
    )
    fidelity.add_argument(
        "--bootstrap",
        type=int,
        default=200,
        metavar="REPLICATES",
        help="moving-block bootstrap replicates of each statistic's standard error on each side, 0 for none "
        "(default: %(default)s, about 3 s)",
    )
    add_progress_option(fidelity)
    fidelity.set_defaults(func=_run_fidelity)
