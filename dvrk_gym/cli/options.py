"""Command-line options several ``dvrk-gym`` commands share: which instrument, what camera,
progress, and where the work runs (local processes or a Dask cluster)."""

from __future__ import annotations

import argparse
import contextlib
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from filelock import FileLock, Timeout

from dvrk_gym.utils.checks import check_endoscope_resolution, check_float, check_int
from dvrk_gym.utils.run_folder import LOCK_FILE

if TYPE_CHECKING:
    from dvrk_gym.parallel.executors import Executor


MAX_CONNECT_TIMEOUT_S = 3600.0
"""The longest ``--connect-timeout``, seconds."""
MAX_TRIALS = 100_000
"""The most ``--trials`` of any command (the paper ran 15 per cell; a trial takes seconds)."""


def check_common_options(args: argparse.Namespace) -> None:
    """Check ``--seed``, ``--bias-seed``, ``--trajectories`` (Phase I's), ``--epochs`` (the
    DNN's), ``--resolution``, ``--connect-timeout`` and ``--trials`` by their flags' names, for every command that has them, before
    the command runs (a config deeper down would name its own field, and a negative seed would
    fail only where numpy first draws from it).

    Raises:
        ValueError: a value out of range.
    """
    for name in ("seed", "bias_seed"):
        if getattr(args, name, None) is not None:
            check_int(f"--{name.replace('_', '-')}", getattr(args, name), 0, 2**31 - 1)
    if getattr(args, "trajectories", None) is not None:
        from dvrk_gym.calibration.phase1 import MAX_TRAJECTORIES

        check_int("--trajectories", args.trajectories, 1, MAX_TRAJECTORIES)
    if getattr(args, "epochs", None) is not None:
        from dvrk_gym.calibration.models.dnn import MAX_EPOCHS

        check_int("--epochs", args.epochs, 1, MAX_EPOCHS)
    if getattr(args, "resolution", None) is not None:
        check_endoscope_resolution("--resolution", args.resolution)
    if getattr(args, "connect_timeout", None) is not None:
        check_float("--connect-timeout", args.connect_timeout, low=0.0, high=MAX_CONNECT_TIMEOUT_S, low_open=True, unit="s")
    if getattr(args, "trials", None) is not None:
        check_int("--trials", args.trials, 1, MAX_TRIALS)


def check_flag_bounds(
    parser: argparse.ArgumentParser, args: argparse.Namespace, bounds: Mapping[str, tuple[float | None, float | None]]
) -> None:
    """Exit with ``parser``'s one-line error (status 2) for a flag outside its bounds, before
    any work: ``{"steps": (1, None)}`` (inclusive; None: unbounded). ``resolution`` is checked
    as an image size (its bounds are ignored); each value of a flag of several is checked;
    flags left at None are not. For the scripts of ``benchmarks/`` as for the commands.
    """
    for name, (low, high) in bounds.items():
        value = getattr(args, name)
        flag = "--" + name.replace("_", "-")
        try:
            if name == "resolution":
                check_endoscope_resolution(flag, value)
            elif value is not None:
                for item in value if isinstance(value, (list, tuple)) else (value,):
                    check_float(flag, item, low=low, high=high)
        except ValueError as error:
            parser.error(str(error))


def add_instrument_options(parser: argparse.ArgumentParser, resolution: bool = True, from_folder: str = "") -> None:
    """``--bias`` and ``--bias-seed`` (the simulated instrument), and ``--resolution`` (the endoscope's image size).

    Args:
        parser: the command's parser.
        resolution: also add ``--resolution W H`` (pixels).
        from_folder: for a command whose run folder (this flag) fixes the instrument: the
            options default to None (the folder's), and the command refuses a value that
            differs from the folder's.
    """
    default_bias, default_seed = ("paper", 0) if not from_folder else (None, None)
    note = f" (default: {from_folder}'s; for a folder with no run yet, %s)" if from_folder else " (default: %s)"
    parser.add_argument("--bias", default=default_bias, help="cable bias preset: none, paper or severe" + note % "paper")
    parser.add_argument("--bias-seed", type=int, default=default_seed, help="which instrument to draw" + note % "0")
    if resolution:
        add_resolution_option(parser, from_folder=from_folder)


def add_resolution_option(parser: argparse.ArgumentParser, from_folder: str = "") -> None:
    """``--resolution W H``: the endoscope's image size, pixels (``from_folder``: as in :func:`add_instrument_options`)."""
    note = f"{from_folder}'s; for a folder with no run yet, 1920 1080" if from_folder else "1920 1080"
    parser.add_argument(
        "--resolution",
        type=int,
        nargs=2,
        default=None if from_folder else (1920, 1080),
        metavar=("W", "H"),
        help=f"endoscope image size in pixels (default: {note})",
    )


def add_progress_option(parser: argparse.ArgumentParser) -> None:
    """``--no-progress``: no progress bars."""
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def add_executor_options(parser: argparse.ArgumentParser, what: str) -> None:
    """``--workers N`` (local processes), ``--scheduler ADDRESS`` (a Dask cluster instead) and
    ``--connect-timeout S``; :func:`make_executor` reads them.

    Args:
        parser: the command's parser.
        what: what runs side by side, for the help texts ("units", "stages").
    """
    where = parser.add_mutually_exclusive_group()  # --workers beside --scheduler was ignored without a word
    where.add_argument(
        "--workers",
        type=int,
        default=min(2, os.cpu_count() or 1),
        help=f"local processes running {what} side by side, without --scheduler (1: in this process); "
        "results do not depend on it (default: %(default)s)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"run the {what} on a Dask cluster instead, e.g. tcp://host:8786 (pip install -e '.[dask]' in a checkout)",
    )
    parser.add_argument(
        "--connect-timeout", type=float, default=10.0, metavar="S", help="seconds to try to reach --scheduler (default: %(default)s)"
    )


def make_executor(args: argparse.Namespace) -> Executor:
    """The executor the options of :func:`add_executor_options` ask for (not yet started).

    Raises:
        ValueError: ``--scheduler`` without dask.distributed installed, a malformed or
            unreachable address, or ``--workers`` below 1.
    """
    if args.scheduler:
        try:
            from dvrk_gym.parallel.dask_executor import DaskExecutor
        except ImportError as error:
            raise ValueError(
                f"--scheduler needs dask.distributed ({error}); install it with: pip install 'dask[distributed]>=2024.1' "
                "(in a checkout of dvrk-gym: pip install -e '.[dask]')"
            ) from None
        return DaskExecutor(args.scheduler, connect_timeout_s=args.connect_timeout)
    from dvrk_gym.parallel.executors import MAX_LOCAL_WORKERS, local_executor
    from dvrk_gym.sim.physics.quiet_import import import_pybullet_quietly

    check_int("--workers", args.workers, 1, MAX_LOCAL_WORKERS)
    return local_executor(args.workers, setup=import_pybullet_quietly)  # no banner from the workers into the progress bar


_created: list[Path] = []
"""Folders :func:`writable_folder` made in this process, deepest first."""


def remove_empty_created_folders() -> None:
    """Remove the folders :func:`writable_folder` made that are still empty, deepest first (a
    command refused after making its ``--out`` leaves nothing behind); folders with files stay.
    A released run lock (an empty ``run.lock`` that nobody holds) counts as nothing: a run
    refused after it opened the folder (an env setting checked when the env is built) leaves no
    folder either. A lock another run holds is left, even empty (just taken, its owner's pid
    not yet written): the lock is taken here before the file is removed, so it is removed only
    while nobody else can hold it."""
    while _created:
        folder = _created.pop(0)
        with contextlib.suppress(OSError, Timeout):  # not empty, gone, or another run's lock: leave it
            lock = folder / LOCK_FILE
            if lock.is_file():
                with FileLock(lock, timeout=0):  # Timeout if another run holds it
                    if lock.stat().st_size == 0 and [entry.name for entry in folder.iterdir()] == [LOCK_FILE]:
                        lock.unlink()
            folder.rmdir()


def _make_folders(path: Path) -> None:
    """Make ``path`` and its missing parents one level at a time, recording in ``_created``
    only those this call made (not one another process made meanwhile)."""
    resolved = path.resolve()  # "new/../keep" names ./keep, not a folder "new" to remove
    for folder in reversed([resolved, *resolved.parents]):
        if folder.exists():
            continue
        try:
            folder.mkdir()
        except FileExistsError:  # made meanwhile by someone else: theirs
            continue
        _created.insert(0, folder)  # deepest first


def forget_created_folders() -> None:
    """Forget the folders :func:`writable_folder` made (a command that succeeded keeps them)."""
    _created.clear()


def writable_folder(path: Path, what: str = "--out") -> Path:
    """``path`` as an output folder that exists and can be written, checked before any work starts.
    The folders it makes are removed by :func:`remove_empty_created_folders` if nothing is written in them.

    Raises:
        NotADirectoryError: ``path`` (or a parent) is a file.
        PermissionError: the folder cannot be written.
    """
    path = Path(path)
    for parent in (path, *path.parents):
        if parent.exists() and not parent.is_dir():
            raise NotADirectoryError(f"{what} {path}: {parent} is a file, not a folder")
    try:
        _make_folders(path)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".write-check-"):
            pass
    except PermissionError:
        raise PermissionError(f"{what} {path}: the folder cannot be written (permission denied)") from None
    except OSError as error:
        raise OSError(f"{what} {path}: the folder cannot be written ({error.strerror or error})") from None
    return path
