"""``dvrk-gym debride``: the paper's debridement trials with a calibrator from a calibration run folder.

Loads the calibrator (:func:`~dvrk_gym.calibration.loading.load_calibrator`; with
``--calibrate`` it runs the two-phase pipeline in the folder first if it holds no model or
a damaged one, without it such a folder is an error), runs the trials
(:func:`~dvrk_gym.evaluation.trials.run_debridement`) with a
:class:`~dvrk_gym.calibration.policy.CalibratedPolicy` aimed at the next fragment the
endoscope sees, prints the trial table and writes it (JSON, text) with a picture of the
outcome grid. The library is imported inside the command, so ``dvrk-gym --help`` stays fast.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dvrk_gym import paper
from dvrk_gym.cli.options import add_instrument_options, add_progress_option, writable_folder
from dvrk_gym.sim.table.contact import CONTACTS, DEFAULT_CONTACT
from dvrk_gym.utils.checks import check_endoscope_resolution, check_int


def _calibration_instrument(args: argparse.Namespace, stamped: dict[str, Any]) -> dict[str, Any]:
    """The instrument and endoscope of the picks: the calibration folder's (``stamped``), else the flags', else the paper's.

    Raises:
        ValueError: a flag that differs from the folder's (it would be ignored), or a folder's value out of range.
    """
    given = {  # the flags' ranges were checked with every command's (cli.options.check_common_options)
        "bias": args.bias,
        "bias_seed": args.bias_seed,
        "camera_resolution": None if args.resolution is None else list(args.resolution),
    }
    for key, flag in (("bias", "--bias"), ("bias_seed", "--bias-seed"), ("camera_resolution", "--resolution")):
        if given[key] is not None and key in stamped and given[key] != stamped[key]:
            raise ValueError(
                f"{flag} {given[key]} differs from the {stamped[key]} that {args.calibration} was calibrated with; the picks "
                f"go through its calibration's instrument and endoscope, so leave {flag} out (or calibrate another folder)"
            )
    defaults = {"bias": "paper", "bias_seed": 0, "camera_resolution": paper.ENDOSCOPE_RESOLUTION_PX}
    world = {key: stamped.get(key, defaults[key] if given[key] is None else given[key]) for key in defaults}
    return {
        "bias": world["bias"],
        "bias_seed": check_int(f"the bias_seed in {args.calibration}'s settings", world["bias_seed"], 0, 2**31 - 1),
        # the picks see through the endoscope the calibration was made with, as its instrument
        "camera_resolution": check_endoscope_resolution(
            f"the camera_resolution in {args.calibration}'s settings", world["camera_resolution"]
        ),
    }


def _run_debride(args: argparse.Namespace) -> int:
    from dvrk_gym.calibration.loading import load_calibrator
    from dvrk_gym.calibration.pipeline import CALIBRATOR_FILES, RETIRED_CALIBRATOR_FILES, read_pipeline_settings
    from dvrk_gym.calibration.policy import CalibratedPolicy
    from dvrk_gym.envs.debridement import fragment_target
    from dvrk_gym.evaluation.trials import cell_label, cell_name, format_trial_table, run_debridement, save_cell

    if args.trials < 1:
        raise ValueError(f"--trials must be >= 1, got {args.trials}")
    model_file = args.calibration / CALIBRATOR_FILES[args.calibrator]
    retired = args.calibration / RETIRED_CALIBRATOR_FILES[args.calibrator]  # load_calibrator says how to remake it
    if not args.calibrate and not model_file.exists() and not retired.exists():
        if args.calibration.is_dir():
            found = "has no " + model_file.name
            if (args.calibration / "calibration" / model_file.name).exists():  # a reproduce run's folder
                found += f" (its calibration is in {args.calibration / 'calibration'})"
        else:
            found = "is a file, not a folder" if args.calibration.exists() else "does not exist"
        raise FileNotFoundError(
            f"--calibration {args.calibration} {found}; give the folder of a calibration run ('dvrk-gym calibrate'), "
            "or add --calibrate to run the calibration there first"
        )
    world = _calibration_instrument(args, read_pipeline_settings(args.calibration) or {})
    writable_folder(args.out)
    calibrator, _ = load_calibrator(args.calibration, args.calibrator, **world, calibrate_if_missing=args.calibrate)
    policy = CalibratedPolicy(calibrator, target=fragment_target)
    trials = run_debridement(
        policy, n_trials=args.trials, seed=args.seed, fragment=args.fragment, **world, progress=not args.no_progress, contact=args.contact
    )
    text = format_trial_table(trials, args.calibrator, args.fragment, args.seed)
    print(text)
    meta = {
        "calibrator": args.calibrator,
        "fragment": args.fragment,
        "seed": args.seed,
        "calibration": str(args.calibration),
        **world,
        "camera_resolution": list(world["camera_resolution"]),
        "contact": args.contact,
    }
    other_paper = args.contact != DEFAULT_CONTACT
    stem = cell_name(args.calibrator, args.fragment) + (f"_{args.contact}" if other_paper else "")
    label = cell_label(args.calibrator, args.fragment) + (f", {args.contact} paper" if other_paper else "")
    written = save_cell(trials, stem=args.out / stem, meta=meta, label=label, text=text)
    print(f"wrote {written['json']}, {written['txt']}, {written['png']}")
    return 0


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``debride``."""
    debride = subparsers.add_parser(
        "debride",
        help="the paper's debridement trials: pick 8 fragments per trial with a calibrator, judged A/B/C",
        description="Loads a calibrator from a calibration run folder (with --calibrate, running the two-phase "
        "pipeline there first if it has no models) and runs debridement trials on Debridement-v0: each pick goes to the next "
        "fragment the endoscope sees, through the calibrator. Prints and writes the paper's trial table "
        "(JSON and text) and a picture of the outcome grid.",
    )
    debride.add_argument(
        "--calibrator", choices=sorted(paper.METHOD_LABELS), default="dnn+rf", help="which calibrator (default: %(default)s)"
    )
    debride.add_argument(
        "--fragment", choices=sorted(paper.FRAGMENT_LABELS), default="pumpkin_seed", help="what to pick (default: %(default)s)"
    )
    debride.add_argument("--trials", type=int, default=paper.DEBRIDEMENT_TRIALS, help="trials of 8 fragments (the paper: %(default)s)")
    debride.add_argument(
        "--calibration", type=Path, default=Path("dvrk_gym_out/calibration"), help="calibration run folder (default: %(default)s)"
    )
    debride.add_argument(
        "--calibrate",
        action="store_true",
        help=(
            "run the two-phase calibration in --calibration first if it holds no model, or a damaged one, which is set "
            "aside as <name>.corrupt (without it, either is an error)"
        ),
    )
    debride.add_argument("--seed", type=int, default=0, help="seeds the trials (default: %(default)s)")
    debride.add_argument(
        "--contact",
        choices=sorted(CONTACTS),
        default=DEFAULT_CONTACT,
        help="the paper under the picks: compliant (jaws sent under the floor they stall on slide along it, as the "
        "authors' records of their table's runs show) or rigid (they stall in place) (default: %(default)s)",
    )
    debride.add_argument("--out", type=Path, default=Path("dvrk_gym_out/debridement"), help="output folder (default: %(default)s)")
    add_instrument_options(debride, from_folder="--calibration")
    add_progress_option(debride)
    debride.set_defaults(func=_run_debride)
