"""The calibration commands of ``dvrk-gym``: collect, calibrate, evaluate, search."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from dvrk_gym import paper
from dvrk_gym.cli.options import add_instrument_options, add_progress_option, writable_folder
from dvrk_gym.evaluation.table_protocol import PROTOCOL_LINES, PROTOCOLS
from dvrk_gym.utils.atomic import atomic_write_json
from dvrk_gym.utils.checks import check_int

DEFAULT_POLICY_ENV = "dvrk_gym/GridTouch-v0"
"""The env ``evaluate --policy`` runs on without ``--env``."""
DEFAULT_POLICY_EPISODES = 35
"""Episodes ``evaluate --policy`` runs without ``--episodes`` (one per printed circle)."""
DEFAULT_CALIBRATION_OUT = Path("dvrk_gym_out/calibration")
"""The calibration's run folder without ``--out`` (``collect``, ``calibrate``, ``evaluate``)."""
DEFAULT_POLICY_OUT = Path("dvrk_gym_out/evaluation")
"""Where ``evaluate --policy`` writes ``evaluation.json`` without ``--out``: not the
calibration's folder, which a file of its own there would keep ``calibrate`` from taking."""


def _add_world_options(parser: argparse.ArgumentParser) -> None:
    add_instrument_options(parser)
    parser.add_argument("--seed", type=int, default=0, help="seeds collection, training and evaluation (default: %(default)s)")


def _add_budget_options(parser: argparse.ArgumentParser, note: str = "") -> None:
    """``--trajectories`` and ``--epochs``: the calibration's budget (None when not given: the paper's)."""
    parser.add_argument("--trajectories", type=int, help=f"Phase I trajectories{note} (default: the paper's {paper.PHASE1_TRAJECTORIES})")
    parser.add_argument("--epochs", type=int, help=f"DNN training epochs{note} (default: the paper's {paper.DNN_EPOCHS})")


def _config(args: argparse.Namespace):
    """The run's PipelineConfig, the paper's budget where ``--trajectories`` or ``--epochs`` is
    not given (every option is checked by its flag's name in ``main``, before any folder is touched)."""
    from dvrk_gym.calibration.pipeline import PipelineConfig

    trajectories = paper.PHASE1_TRAJECTORIES if args.trajectories is None else args.trajectories
    epochs = paper.DNN_EPOCHS if args.epochs is None else args.epochs
    return PipelineConfig(
        n_trajectories=trajectories,
        dnn_epochs=epochs,
        bias=args.bias,
        bias_seed=args.bias_seed,
        camera_resolution=tuple(args.resolution),
        seed=args.seed,
    )


def _run_collect(args: argparse.Namespace) -> int:
    """Phase I into ``--out``, stamped as ``dvrk-gym calibrate`` with the same options stamps its
    folder (calibrate's default epochs): a calibrate there resumes from it, and a folder stamped
    with other settings, or by another dvrk_gym, is refused before anything is collected."""
    import dataclasses

    from dvrk_gym.calibration.phase1 import Phase1Data, run_paper_phase1
    from dvrk_gym.calibration.pipeline import SETTINGS_STAMP
    from dvrk_gym.utils.run_folder import RunFolder

    config = _config(args)
    with RunFolder(writable_folder(args.out), dataclasses.asdict(config), stamp=SETTINGS_STAMP) as folder:
        path = folder.file("phase1.npz")

        def collect() -> Phase1Data:
            return run_paper_phase1(
                n_trajectories=config.n_trajectories,
                seed=config.seed,
                steps_per_trajectory=config.steps_per_trajectory,
                **config.env_kwargs(),
                progress=not args.no_progress,
            )

        if args.force:  # the old file stays until the new one is written (atomically)
            data = collect()
            data.save(path)
        else:  # one already there is these settings' (the folder's stamp): loaded, as calibrate would
            data = folder.cached("phase1.npz", make=collect, load=Phase1Data.load, save=lambda value, where: value.save(where))
        made = args.force or "phase1" in folder.made_s
    raw, kept = paper.PHASE1_RAW_SAMPLES, paper.PHASE1_KEPT_SAMPLES
    print(
        f"Phase I: {args.trajectories} trajectories, {data.n_raw} raw samples, {data.n_kept} kept "
        f"({data.n_kept / data.n_raw:.0%}; the paper: {raw} and {kept}, {kept / raw:.0%})"
    )
    print(f"wrote {path}" if made else f"loaded {path}, made by an earlier run with these settings (--force collects again)")
    return 0


def _run_calibrate(args: argparse.Namespace) -> int:
    from dvrk_gym.calibration.pipeline import CALIBRATOR_FILES, run_calibration

    config = _config(args)  # checked before the folder is made or stamped
    result = run_calibration(writable_folder(args.out), config, progress=not args.no_progress, benchmark=False)
    phase1 = result["phase1"]
    print(f"Phase I: {phase1.n_raw} raw, {phase1.n_kept} kept; Phase II: {len(result['phase2'].circle)} corrections")
    print(f"models in {args.out}: {', '.join(CALIBRATOR_FILES.values())} (skops forests, safetensors weights: no pickles)")
    print(_stages_note(result["timings_s"], args.out))
    return 0


def _stages_note(timings_s: dict[str, float], out: Path) -> str:
    """Which of the calibration's stages this run made, and that the others came from ``out``'s cache."""
    from dvrk_gym.calibration.pipeline import STAGES

    made = [stage for stage in timings_s if stage != "benchmark"]
    if not made:
        return f"every stage loaded from {out} (made by an earlier run with these settings)"
    return f"made now: {', '.join(made)}" + ("" if len(made) == len(STAGES) else f"; the others loaded from {out}")


def _run_evaluate(args: argparse.Namespace) -> int:
    if args.out is None:
        args.out = DEFAULT_POLICY_OUT if args.policy else DEFAULT_CALIBRATION_OUT
    if args.policy:
        if args.protocol is not None:
            raise ValueError("--protocol is how the calibrators' predictions are sent; a --policy sends its own actions as they are")
        given = [flag for flag in ("--trajectories", "--epochs") if getattr(args, flag[2:]) is not None]
        if given:
            raise ValueError(f"{' and '.join(given)} set the calibration's budget; a --policy is evaluated as it is")
        return _evaluate_policy(args)
    given = [flag for flag in ("--env", "--episodes", "--options") if getattr(args, flag[2:]) is not None]
    if given:
        verb = "applies" if len(given) == 1 else "apply"
        raise ValueError(f"{' and '.join(given)} {verb} to --policy only; without --policy, evaluate runs the paper's calibration table")
    from dvrk_gym.calibration.benchmark import format_table
    from dvrk_gym.calibration.pipeline import run_calibration

    protocol = args.protocol or "paper"
    config = _config(args)  # checked before the folder is made or stamped
    result = run_calibration(writable_folder(args.out), config, progress=not args.no_progress, benchmark=True, protocol=protocol)
    print(PROTOCOL_LINES[protocol])
    print(format_table(result["table"]))
    print(f"wrote {args.out / 'calibration_table.json'}, {args.out / 'calibration_table.txt'}, {args.out / 'calibration_error_maps.png'}")
    print(_stages_note(result["timings_s"], args.out))
    return 0


def _evaluate_policy(args: argparse.Namespace) -> int:
    from dvrk_gym.envs import ENV_CONFIGS
    from dvrk_gym.evaluation.episodes import as_policy, evaluate_policy, load_policy_factory, summarize_metric

    args.env = DEFAULT_POLICY_ENV if args.env is None else args.env
    args.episodes = DEFAULT_POLICY_EPISODES if args.episodes is None else args.episodes
    if args.env not in ENV_CONFIGS:
        raise ValueError(f"--env must be one of dvrk_gym's envs {sorted(ENV_CONFIGS)}, got {args.env!r}")
    check_int("--episodes", args.episodes, 1, 10**6)
    factory = load_policy_factory(args.policy)  # a bad name fails before any env is built
    try:
        options = json.loads(args.options) if args.options else None
    except ValueError as error:
        raise ValueError(f"--options must be a JSON object, got {args.options!r} ({error})") from None
    if options is not None and not isinstance(options, dict):
        raise ValueError(f"--options must be a JSON object, got {args.options!r}")
    writable_folder(args.out)
    world = {"bias": args.bias, "bias_seed": args.bias_seed, "camera_resolution": tuple(args.resolution)}

    def checked(env: Any) -> Any:  # what the factory made must be a policy: one line, not a traceback from the first step
        policy = factory(env)
        try:
            as_policy(policy)
        except TypeError as error:
            raise ValueError(f"--policy {args.policy} made no policy: {error}") from None
        return policy

    results = evaluate_policy(
        checked, args.env, n_episodes=args.episodes, seed=args.seed, options=options, progress=not args.no_progress, **world
    )
    names = sorted({name for r in results for name in r.metrics})
    print(f"{args.policy} on {args.env}, {args.episodes} episodes (seed {args.seed})")
    print(f"{'metric':<22}{'mean':>10}{'s.e.':>9}{'median':>10}{'min':>10}{'max':>10}")
    for name in names:
        stats = summarize_metric(results, name)
        print(f"{name:<22}{stats['mean']:>10.3f}{stats['sem']:>9.3f}{stats['median']:>10.3f}{stats['min']:>10.3f}{stats['max']:>10.3f}")
    path = atomic_write_json(
        args.out / "evaluation.json", [{"options": r.options, "metrics": r.metrics} for r in results], indent=1, default=str
    )
    print(f"wrote {path}")
    return 0


def _run_search(args: argparse.Namespace) -> int:

    from dvrk_gym.calibration.datasets import load_paper_phase1
    from dvrk_gym.calibration.phase1 import Phase1Data
    from dvrk_gym.calibration.search import format_table, plot_search, run_search, search_caption

    check_int("--folds", args.folds, 2, 1000)
    if args.data == "paper":
        X, y = load_paper_phase1()
        source = "the authors' real Phase I data"
    else:
        clean = Phase1Data.load(args.data).cleaned()
        X, y = clean.X, clean.y
        source = str(args.data)
    if args.folds > len(X):
        raise ValueError(f"--folds {args.folds}: {source} has only {len(X)} rows that the cleaning keeps")
    writable_folder(args.out)
    split = args.split or ("contiguous" if args.data == "paper" else "shuffled")
    shuffle, progress = split == "shuffled", not args.no_progress
    results = run_search(X, y, folds=args.folds, seed=args.seed, quick=args.quick, shuffle=shuffle, progress=progress)
    caption = f"{search_caption(results)}. Data: {source}, {len(X)} rows."
    print(format_table(results, caption))
    plot_search(results, str(args.out / "model_search.png"), caption)
    rows = [
        {
            "name": r.name,
            "family": r.family,
            "mean_mm2": r.mean_mm2,
            "std_mm2": r.std_mm2,
            "folds_mm2": list(r.fold_mm2),
            "epochs": r.epochs,
            "split": split,
        }
        for r in results
    ]
    atomic_write_json(args.out / "model_search.json", rows, indent=1)
    print(f"wrote {args.out / 'model_search.png'}, {args.out / 'model_search.json'} ({len(results)} models)")
    return 0


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register collect, calibrate, evaluate and search."""
    collect = subparsers.add_parser(
        "collect",
        help="Phase I: run the paper's random exploration and save the data",
        description="Collect the paper's Phase I in --out (phase1.npz: the raw rows and the kept ones), as the authors' "
        "collector ran it: trajectories from the four corners, a pause every 2 mm, random rotations at each pause. The "
        "folder is stamped as calibrate stamps it, so `dvrk-gym calibrate --out` with the same options (and its default --epochs) "
        "resumes from it.",
    )
    collect.add_argument("--out", type=Path, default=DEFAULT_CALIBRATION_OUT, help="output folder (default: %(default)s)")
    collect.add_argument("--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="trajectories (the paper: %(default)s)")
    collect.add_argument(
        "--force",
        action="store_true",
        help="collect again, replacing a phase1.npz already in --out (without it, one made with the same settings is loaded)",
    )
    _add_world_options(collect)
    add_progress_option(collect)
    collect.set_defaults(func=_run_collect, epochs=paper.DNN_EPOCHS)  # no --epochs: its stamp holds calibrate's default

    calibrate = subparsers.add_parser(
        "calibrate",
        help="Phase I and II: fit the rigid body, DNN and DNN+RF calibrators (cached stages)",
        description="Run the paper's two-phase calibration in --out: Phase I (collect, or the folder's cached phase1.npz), "
        "the rigid body and the DNN fitted to it, Phase II (a simulated person's corrections at 5 yaws x 35 circles) and "
        "the residual forests. Every stage is cached in --out, so the same command resumes; a folder made with other "
        "settings or by another dvrk_gym is refused.",
    )
    calibrate.add_argument("--out", type=Path, default=DEFAULT_CALIBRATION_OUT, help="output folder (default: %(default)s)")
    _add_budget_options(calibrate)
    _add_world_options(calibrate)
    add_progress_option(calibrate)
    calibrate.set_defaults(func=_run_calibrate)

    evaluate = subparsers.add_parser(
        "evaluate",
        help="the paper's calibration table (RBT, DNN, DNN+RF x six yaw settings), or any policy with --policy",
        description="Without --policy: calibrate (resuming cached stages in --out) and produce the paper's table "
        "'Calibration Error Results' with per-circle error maps. With --policy module:factory: run that policy "
        "(factory(env) -> policy) on --env and summarise every metric.",
    )
    evaluate.add_argument(
        "--out",
        type=Path,
        help=f"output folder (default: {DEFAULT_CALIBRATION_OUT}; with --policy, {DEFAULT_POLICY_OUT}, where it writes evaluation.json)",
    )
    evaluate.add_argument("--policy", help="evaluate another policy: 'package.module:factory', factory(env) returns the policy")
    evaluate.add_argument("--env", help=f"environment for --policy (default: {DEFAULT_POLICY_ENV})")
    evaluate.add_argument("--episodes", type=int, help=f"episodes for --policy (default: {DEFAULT_POLICY_EPISODES})")
    evaluate.add_argument("--options", help='reset options for --policy as JSON, e.g. \'{"yaw": "random"}\'')
    evaluate.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default=None,
        help="how the calibrators' predictions are sent: 'paper', as the authors' runs did (the rigid body's heights lifted "
        "4-9 mm, and clipped in three settings), or 'raw', as they are (default: paper)",
    )
    _add_budget_options(evaluate, note=", without --policy")
    _add_world_options(evaluate)
    add_progress_option(evaluate)
    evaluate.set_defaults(func=_run_evaluate)

    search = subparsers.add_parser(
        "search",
        help="the paper's model search: 24 nets, linear and forests by cross-validation, with its bar chart",
        description="Cross-validate the paper's candidate models (24 nets, linear regressions, random forests) on the "
        "authors' real Phase I rows or a phase1.npz, and draw the paper's bar chart. The chosen net, the linear models "
        "and the forests are scored on every fold; to keep the search near half an hour of CPU, the 23 other nets on the "
        "first 3 folds (the caption says so; the Python API's sweep_folds=None scores them all).",
    )
    search.add_argument(
        "--data", default="paper", help="'paper' (the authors' real data) or a phase1.npz from collect (default: %(default)s)"
    )
    search.add_argument("--out", type=Path, default=Path("dvrk_gym_out/search"), help="output folder (default: %(default)s)")
    search.add_argument("--folds", type=int, default=paper.SEARCH_FOLDS, help="cross-validation folds (default: %(default)s)")
    search.add_argument(
        "--split",
        choices=("contiguous", "shuffled"),
        help="contiguous folds in row order, as the authors ran their search, or shuffled ones "
        "(default: contiguous for --data paper, shuffled for a file)",
    )
    search.add_argument("--seed", type=int, default=0, help="seeds the models, and shuffled folds (default: %(default)s)")
    search.add_argument("--quick", action="store_true", help="a few models, few epochs, at most 3 folds (it caps --folds)")
    add_progress_option(search)
    search.set_defaults(func=_run_search)
