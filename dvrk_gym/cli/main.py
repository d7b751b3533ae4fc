"""The ``dvrk-gym`` command line."""

from __future__ import annotations

import argparse
import contextlib
import difflib
import logging
import os
import re
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TextIO

from dvrk_gym import __version__
from dvrk_gym.cli.baselines import TRAINING_STATE, training_folder
from dvrk_gym.cli.baselines import add_commands as add_baseline_commands
from dvrk_gym.cli.calibration import add_commands as add_calibration_commands
from dvrk_gym.cli.debridement import add_commands as add_debridement_commands
from dvrk_gym.cli.demo import add_commands as add_demo_commands
from dvrk_gym.cli.fidelity import add_commands as add_fidelity_commands
from dvrk_gym.cli.options import check_common_options, forget_created_folders, remove_empty_created_folders
from dvrk_gym.cli.reproduce import add_commands as add_reproduce_commands
from dvrk_gym.cli.sweep import add_commands as add_sweep_commands
from dvrk_gym.sim.physics.quiet_import import import_pybullet_quietly
from dvrk_gym.utils.run_folder import RunFolderBusy

Command = Callable[[argparse.Namespace], int]


CONFIG_CLASSES = (
    "BiasConfig",
    "DebridementConfig",
    "EnvConfig",
    "ExplorationConfig",
    "GridTouchConfig",
    "GripperConfig",
    "PipelineConfig",
    "ReproduceConfig",
    "TrainConfig",
    "WorldConfig",
)
"""dvrk_gym's config classes, whose checks name a field as ``TrainConfig.n_envs`` (a test keeps the list whole)."""
_CONFIG_FIELD = re.compile(rf"(?<![\w./\\-])(?:{'|'.join(CONFIG_CLASSES)})\.(\w+)\b")
"""A config's field as its check names it, not inside a path or a longer name."""


def _one_line(error: BaseException, args: argparse.Namespace) -> str:
    """An error's message on one line (an OSError without its own words gets its errno's),
    naming the command's flag where a config deeper down named its own field
    (``TrainConfig.n_envs`` -> ``--n-envs``: every flag's dest is its name, dashes as underscores)."""
    text = " ".join((str(error) or type(error).__name__).split())

    def flag(match: re.Match[str]) -> str:
        field = match.group(1)
        return f"--{field.replace('_', '-')}" if not field.startswith("_") and getattr(args, field, None) is not None else match.group(0)

    return _CONFIG_FIELD.sub(flag, text)


def keeps_work_when_interrupted(args: argparse.Namespace) -> bool:
    """Whether an interrupted run of this command keeps finished stages that the same command
    picks up again: the calibration pipeline's cached stages (calibrate, evaluate without
    --policy, debride --calibrate), reproduce's and sweep's tasks (a training's saved state:
    :func:`interrupted_note`)."""
    if args.command in ("calibrate", "reproduce", "sweep"):
        return True
    if args.command == "evaluate":
        return not args.policy
    if args.command == "debride":
        return bool(args.calibrate)
    return False


def interrupted_note(args: argparse.Namespace) -> str:
    """What an interrupted run of this command kept, and what running it again does."""
    if args.command == "baseline" and args.baseline_command == "train":
        if (training_folder(args) / TRAINING_STATE).exists():
            return "its last saved training state is kept: the same command resumes from it"
        return f"nothing is kept: no training state was saved yet (the first save comes after {args.save_every} env steps); run it again"
    return "cached stages are kept: the same command resumes" if keeps_work_when_interrupted(args) else "nothing is kept: run it again"


EXAMPLES = {
    "reproduce": ["dvrk-gym reproduce --quick", "dvrk-gym reproduce --out runs/paper"],
    "demo": ["dvrk-gym demo --out runs/demo"],
    "collect": ["dvrk-gym collect --trajectories 3 --resolution 640 360 --out runs/cal"],
    "calibrate": ["dvrk-gym calibrate --out runs/cal"],
    "evaluate": ["dvrk-gym evaluate --out runs/cal", "dvrk-gym evaluate --policy pkg.module:factory --episodes 20"],
    "search": ["dvrk-gym search --out runs/search"],
    "fidelity": ["dvrk-gym fidelity --bias paper --bias-seed 0 --out runs/fidelity"],
    "debride": ["dvrk-gym debride --calibrator dnn+rf --fragment pumpkin_seed --trials 15 --calibration runs/cal"],
    "baseline train": ["dvrk-gym baseline train --algo sac_her --out runs/sac_her"],
    "baseline evaluate": ["dvrk-gym baseline evaluate --model runs/sac_her/model.zip --calibration runs/cal"],
    "sweep": ["dvrk-gym sweep --bias-seeds 0-4 --seeds 0 --out runs/sweep"],
}
"""Each command's examples, shown under its ``--help`` (a test parses every one)."""


class _CommandLineParser(argparse.ArgumentParser):
    """The top-level parser: an unknown argument is refused with its command's usage (not the
    top level's) and the options it may have meant (``--qiuck``: did you mean ``--quick``?)."""

    def parse_args(self, args: Sequence[str] | None = None, namespace: Any = None) -> Any:  # type: ignore[override]
        parsed, unknown = self.parse_known_args(args, namespace)
        if unknown:
            command: argparse.ArgumentParser = getattr(parsed, "command_parser", self)
            options = [option for action in command._actions for option in action.option_strings]
            near = sorted(
                {match for token in unknown for match in difflib.get_close_matches(token.split("=")[0], options, n=2, cutoff=0.75)}
            )
            hint = f" (did you mean {' or '.join(near)}?)" if near else ""
            command.error(f"unrecognized arguments: {' '.join(unknown)}{hint}")
        return parsed


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``dvrk-gym`` command."""
    parser = _CommandLineParser(
        prog="dvrk-gym",
        description="Simulated dVRK calibration and debridement (Seita et al., ICRA 2018).",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    parser.add_argument("--version", action="version", version=f"dvrk-gym {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_reproduce_commands(subparsers)
    add_demo_commands(subparsers)
    add_calibration_commands(subparsers)
    add_fidelity_commands(subparsers)
    add_debridement_commands(subparsers)
    add_baseline_commands(subparsers)
    add_sweep_commands(subparsers)
    for command in _leaf_parsers(parser):
        command.set_defaults(command_parser=command)  # an unknown argument is named with the command's own usage
        examples = EXAMPLES[command.prog.removeprefix("dvrk-gym ")]
        command.epilog = f"example{'s' if len(examples) > 1 else ''}: " + "; ".join(examples)
        command.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="log progress details")
    return parser


def _leaf_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """The parsers of the commands that run (``baseline train``, not ``baseline``)."""
    groups = [action for action in parser._actions if isinstance(action, argparse._SubParsersAction)]
    if not groups:
        return [parser]
    return [leaf for group in groups for command in dict.fromkeys(group.choices.values()) for leaf in _leaf_parsers(command)]


def _command(args: argparse.Namespace) -> str:
    """The command as typed: ``"baseline train"`` for a subcommand."""
    return " ".join(filter(None, (args.command, getattr(args, "baseline_command", None))))


PIPED_PROGRESS_INTERVAL_S = 10.0
"""How often a progress bar is redrawn when standard error is no terminal (a batch job's log
file, ``2>&1 | tee``), seconds: tqdm's 0.1 s wrote megabytes of redrawn bars into a long
run's log. Read by tqdm from ``TQDM_MININTERVAL`` when it is imported; one set by the user wins."""


@contextlib.contextmanager
def _bars_for(stream: TextIO) -> Iterator[None]:
    """Progress bars redrawn every :data:`PIPED_PROGRESS_INTERVAL_S` while ``stream`` is no terminal."""
    piped = not stream.isatty() and "TQDM_MININTERVAL" not in os.environ
    if piped:
        os.environ["TQDM_MININTERVAL"] = f"{PIPED_PROGRESS_INTERVAL_S:g}"
    try:
        yield
    finally:
        if piped:
            os.environ.pop("TQDM_MININTERVAL", None)


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived (``kill``, ``timeout``, a batch system ending the job): stop as Ctrl-C does."""


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """While in the block, SIGTERM raises :class:`Terminated` in the main thread, so a
    terminated command stops its workers, keeps its finished stages and says so, as after
    Ctrl-C (by default SIGTERM ended the process at once: no note, and the multiprocessing
    semaphores of its pool left behind). Off the main thread, where no handler can be set,
    nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum: int, frame: object) -> None:
        raise Terminated

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)  # None: set outside Python


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dvrk-gym`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    forget_created_folders()  # only this command's folders are removed if it is refused
    import_pybullet_quietly()  # its build-time banner would make every error two lines
    try:
        with _terminate_as_interrupt(), _bars_for(sys.stderr):  # before the checks, whose imports may bring tqdm in
            check_common_options(args)
            return int(args.func(args))
    except (ValueError, OSError, RunFolderBusy) as error:  # bad input, unwritable output, a folder in use: one line, status 2
        remove_empty_created_folders()
        print(f"dvrk-gym {_command(args)}: error: {_one_line(error, args)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as stop:
        remove_empty_created_folders()
        terminated = isinstance(stop, Terminated)
        print(f"dvrk-gym {_command(args)}: {'terminated' if terminated else 'interrupted'} ({interrupted_note(args)})", file=sys.stderr)
        return 128 + (signal.SIGTERM if terminated else signal.SIGINT)  # 143 or 130, as the shells report a death by it
    except BaseException:  # anything else (a policy of the user's raising, a bug): its traceback, and no empty folder
        remove_empty_created_folders()
        raise


if __name__ == "__main__":
    sys.exit(main())
