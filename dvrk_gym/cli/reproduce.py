"""``dvrk-gym reproduce``: the paper end to end in simulation, with a report beside the paper."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dvrk_gym.cli.options import add_executor_options, add_instrument_options, add_progress_option, make_executor, writable_folder

DEFAULT_OUT = {"quick": Path("dvrk_gym_out/reproduce-quick"), "full": Path("dvrk_gym_out/reproduce")}
"""The default run folder by profile name (another profile's: dvrk_gym_out/reproduce-<name>)."""


def _run_reproduce(args: argparse.Namespace) -> int:
    from dvrk_gym.parallel.task_graph import TaskError
    from dvrk_gym.reproduce import PROFILES, Profile, ReproduceConfig, run_reproduce

    if args.profile is not None:
        if args.quick:
            raise ValueError("give --quick or --profile, not both")
        profile = Profile.from_file(args.profile)
    else:
        profile = PROFILES["quick" if args.quick else "full"]
    out = writable_folder(args.out or DEFAULT_OUT.get(profile.name, Path(f"dvrk_gym_out/reproduce-{profile.name}")))
    config = ReproduceConfig(
        out=out,
        profile=profile,
        seed=args.seed,
        workers=args.workers,
        bias=args.bias,
        bias_seed=args.bias_seed,
        progress=not args.no_progress,
    )
    executor = make_executor(args)
    print(f"reproduce: profile {profile.name}, tasks on {executor.description}, run folder {out}")
    try:
        with executor:
            run = run_reproduce(config, executor)
    except TaskError as error:
        print(
            f"dvrk-gym reproduce: {error}\n(the stages that finished are cached in {out}: once the cause is mended, the "
            "same command resumes from them; other settings need another --out)",
            file=sys.stderr,
        )
        return 1
    calibration = run.data["calibration"]
    print()
    print(f"{'method':<10}{'sim mm':>8}{'paper mm':>10}")
    for method, row in calibration.items():
        paper = row["paper_mean_mm"]
        print(f"{method:<10}{row['mean_mm']:>8.2f}{(paper if paper is not None else float('nan')):>10.2f}")
    for cell in run.data["debridement"]:
        paper = cell["paper"]
        paper_text = f"   paper {paper['success']}/120" if paper else ""
        print(f"debridement {cell['method']:<14}{cell['fragment']:<14}{cell['success']:>4}/{cell['picks']:<4}{paper_text}")
    for agent in run.data["rl"]:
        print(f"RL {agent['label']}: {agent['mean_mm']:.2f} mm after {agent['env_steps']:,} moves")
    print(f"\nwrote {run.report}, {run.results} and figures in {out / 'figures'} ({run.wall_s:.0f} s)")
    return 0


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``reproduce``."""
    parser = subparsers.add_parser(
        "reproduce",
        help="reproduce the paper end to end: calibration, model search, debridement, RL baseline; report.md",
        description="Runs the paper's experiment in simulation: Phase I collection, the model search, the DNN, "
        "Phase II, the residual forests, the calibration table, the debridement tables (both fragments, DNN and "
        "DNN+RF), time per fragment, and an RL baseline trained for the calibrator's robot moves. Writes report.md "
        "(each table beside the paper's numbers, with the difference), results.json and PNG figures. Stages are "
        "cached in the output folder: a re-run resumes. --quick: a five-model search, 3 trials per debridement "
        "cell and a short RL run (a few minutes on 2 cores); the full run took 21 min with 2 workers on "
        "a quiet 2-core machine, and 50 with other work beside it (README: Reproducing the paper, Measured performance). --scheduler runs "
        "the stages on a Dask cluster, with the same "
        "results; its workers must see --out at the same path (a shared disk).",
    )
    parser.add_argument("--quick", action="store_true", help="the quick profile (a few minutes) instead of the full run")
    parser.add_argument(
        "--profile",
        type=Path,
        metavar="FILE",
        help="a custom profile: a JSON object of dvrk_gym.reproduce.Profile's fields, e.g. "
        '{"name": "tiny", "n_trajectories": 2, "debridement_trials": 1} (the others keep the full run\'s values)',
    )
    parser.add_argument(
        "--out", type=Path, help="run folder (default: dvrk_gym_out/reproduce-quick, dvrk_gym_out/reproduce, or reproduce-<profile name>)"
    )
    add_executor_options(parser, "stages")
    parser.add_argument("--seed", type=int, default=0, help="seeds every stage (default: %(default)s)")
    add_instrument_options(parser, resolution=False)
    add_progress_option(parser)
    parser.set_defaults(func=_run_reproduce)
