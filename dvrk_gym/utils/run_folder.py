"""A run folder: results cached on disk for one set of settings, owned by one run at a time.

A folder opened with settings is stamped with them (a JSON file in the folder); opening it
again with other settings is refused with an error that names what differs, so results
made with one set of settings are never mixed with another's (a folder holding no result but
stamps, locks and empty folders, from a run refused before it made anything, takes new ones).
The stamp also records which dvrk_gym made the results (:func:`~dvrk_gym.utils.source_fingerprint.source_fingerprint`,
under the reserved key :data:`SOURCE_KEY`): a folder stamped by another version of the
simulator, whose code (its identified instrument, its collector...) changes between
versions, or by one from before stamps had it, is refused too; and so is a folder that
holds files but no stamp (one deleted, say): their settings are unknown. Each result is a
file: :meth:`RunFolder.cached` loads it when it is there, else makes and saves it, and one
that cannot be read back (cut short by a full disk, edited by hand) is named in a warning,
set aside as ``<name>.corrupt`` (:func:`~dvrk_gym.utils.atomic.set_aside`) and made again.

One run owns a folder at a time: opening it takes a lock (``run.lock``, a
:class:`filelock.FileLock` holding the owner's process id), and a second process that
opens it gets :class:`RunFolderBusy`, naming the folder and the owner. The kernel drops
the lock when its owner dies, however it dies; the next run takes the folder over with a
logged message naming the dead owner. Within one process the lock is re-entrant. Every
file is written atomically (:mod:`dvrk_gym.utils.atomic`), and the temporary files an
interrupted write left behind are removed when the folder is opened.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import stat
import time
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from filelock import FileLock, Timeout

from dvrk_gym.utils.atomic import atomic_path, atomic_write_json, read_json, remove_partial_files, set_aside
from dvrk_gym.utils.source_fingerprint import SourceFingerprint, source_fingerprint

logger = logging.getLogger(__name__)

T = TypeVar("T")

LOCK_FILE = "run.lock"
"""The lock file of a run folder; it holds the owner's process id while a run owns the folder."""
UNREADABLE = (ValueError, OSError, EOFError, KeyError, TypeError, zipfile.BadZipFile)
"""What a loader raises on a file cut short or tampered with (JSON and model-file errors are ValueErrors)."""
SOURCE_KEY = "dvrk_gym_source"
"""A stamp's key for the fingerprint of the dvrk_gym that made the folder's results
(:meth:`SourceFingerprint.to_json`); reserved, and left out by :func:`read_settings`."""


class RunFolderBusy(RuntimeError):
    """Another process owns the run folder (the message names the folder and the owner's process id)."""


def flatten_settings(value: Any, prefix: str = "") -> dict[str, Any]:
    """A JSON tree (nested dicts) as ``{"a.b": leaf}`` (lists are leaves)."""
    if not isinstance(value, dict):
        return {prefix: value}
    flat: dict[str, Any] = {}
    for key, item in value.items():
        flat.update(flatten_settings(item, f"{prefix}.{key}" if prefix else str(key)))
    return flat


def settings_differences(found: Any, wanted: Any) -> list[str]:
    """What differs between two JSON settings trees: ``["seed: 0 there, 1 here", ...]``."""
    there, here = flatten_settings(found), flatten_settings(wanted)
    missing = object()
    return [
        f"{key}: {there.get(key, 'unset')!r} there, {here.get(key, 'unset')!r} here"
        for key in sorted(set(there) | set(here))
        if there.get(key, missing) != here.get(key, missing)
    ]


def _read_stamp(path: Path) -> dict[str, Any] | None:
    """A stamp file's JSON object as written (settings and source fingerprint), or None when there is none."""
    if not path.exists():
        return None
    try:
        stamp = read_json(path)
    except (ValueError, OSError) as error:
        raise ValueError(f"{path} is unreadable ({error}); delete the folder to start the run again") from None
    if not isinstance(stamp, dict):
        raise ValueError(f"{path} holds {type(stamp).__name__}, not the settings object this tool writes; delete the folder")
    return stamp


def read_settings(folder: str | os.PathLike, stamp: str) -> dict[str, Any] | None:
    """The settings a folder was stamped with (without its source fingerprint), or None when it has no stamp.

    Raises:
        ValueError: the stamp is not a JSON object (the message names the file).
    """
    found = _read_stamp(Path(folder) / stamp)
    return None if found is None else {key: value for key, value in found.items() if key != SOURCE_KEY}


RESUME_REMEDY = "use another --out, or delete the folder to make them again with this version"
"""What :class:`RunFolder`'s refusal of another dvrk_gym's folder tells the user to do."""


def _refuse_other_source(stamp: Path, recorded: Any, here: SourceFingerprint, remedy: str) -> None:
    """Refuse (ValueError) results whose stamp says another dvrk_gym made them, or does not say which did."""
    folder = stamp.parent
    there = SourceFingerprint.from_json(recorded)
    if there is None:
        why = "has no source fingerprint" if recorded is None else f"has an unreadable source fingerprint ({str(recorded)[:80]})"
        raise ValueError(
            f"{folder} holds results made by an older dvrk_gym: its stamp ({stamp.name}) {why}, so which "
            f"simulator made them is unknown and {here.short()} cannot use them with its own; {remedy}"
        )
    if there.sha256 != here.sha256:
        raise ValueError(
            f"{folder} holds results made by another version of dvrk_gym's simulator ({there.short()}; this is "
            f"{here.short()}), which would be mixed with this version's; {remedy}"
        )


def check_made_here(folder: str | os.PathLike, stamp: str, remedy: str) -> None:
    """Refuse a stamped folder that another dvrk_gym made, as :class:`RunFolder` refuses to resume
    one, for a reader that mixes the folder's results with this version's without writing
    there (a benchmark that reads a calibration's Phase I and simulates more). A folder
    without the stamp passes: whether it is a run folder at all is the caller's question.

    Args:
        folder: the run folder.
        stamp: the name of its settings stamp.
        remedy: what the message tells the user to do instead.

    Raises:
        ValueError: the stamp records another dvrk_gym's source fingerprint or none (the
            message names both fingerprints and ``remedy``), or is no readable JSON object.
    """
    found = _read_stamp(Path(folder) / stamp)
    if found is not None:
        _refuse_other_source(Path(folder) / stamp, found.get(SOURCE_KEY), source_fingerprint(), remedy)


MAX_LOCK_BYTES = 4096
"""The most of a lock file read, bytes (it holds a short JSON object)."""


def _lock_text(lock_file: Path) -> str:
    """What a lock file holds (its first :data:`MAX_LOCK_BYTES`), or "" when there is none.

    Raises:
        ValueError: the path is not a regular file (a FIFO there would block the read).
    """
    try:
        status = lock_file.stat()
    except FileNotFoundError:
        return ""
    if not stat.S_ISREG(status.st_mode):
        raise ValueError(f"{lock_file} is not a regular file; delete it (it should be the run's lock file)")
    with lock_file.open("rb") as file:
        return file.read(MAX_LOCK_BYTES).decode("utf-8", errors="replace")


def _owner_pid(text: str) -> int | None:
    """The process id a lock file holds, or None when it holds none (a clean release empties it)."""
    try:
        return int(json.loads(text)["pid"])
    except (ValueError, KeyError, TypeError):
        return None


MAX_STAMP_BYTES = 2**20
"""The largest JSON file read as a possible stamp of a run folder below another, bytes (stamps take about 1 kB)."""


def _is_stamped_run_folder(folder: Path) -> bool:
    """Whether ``folder`` is a run folder with a lock and a stamp of its own, which checks its results."""
    return (folder / LOCK_FILE).exists() and any(_is_stamp(path) for path in folder.glob("*.json"))


def _is_stamp(path: Path) -> bool:
    """Whether ``path`` is a run folder's stamp: a JSON object recording a source fingerprint."""
    with contextlib.suppress(ValueError, OSError):
        stamp = read_json(path, max_bytes=MAX_STAMP_BYTES)
        return isinstance(stamp, dict) and SOURCE_KEY in stamp
    return False


def _unstamped_files(folder: Path) -> list[str]:
    """The files in ``folder`` and below (caches such as ``tasks/``), relative to it, sorted; but
    locks, hidden (temporary) files and stamped run folders below (a calibration's ``runs/cal``)."""
    found = []
    for here, folders, files in os.walk(folder):
        folders[:] = sorted(name for name in folders if not _is_stamped_run_folder(Path(here) / name))
        for name in files:
            if not name.startswith(".") and name != LOCK_FILE and (Path(here) / name).is_file():
                found.append(str((Path(here) / name).relative_to(folder)))
    return sorted(found)


def _refuse_unstamped_files(folder: Path, stamp: Path) -> None:
    """Refuse ``folder`` when it holds files and ``stamp`` is missing: nobody recorded their settings."""
    if not stamp.exists() and (unknown := _unstamped_files(folder)):
        listed = f"{unknown[:5]}{' ...' if len(unknown) > 5 else ''}"
        raise ValueError(
            f"{folder} holds files but no settings stamp ({stamp.name}): {listed} were made with settings nobody recorded; "
            "use an empty folder, or delete these"
        )


def _holds_results(folder: Path, stamp: Path) -> bool:
    """Whether ``folder`` or one below it holds a file but stamps, locks and hidden (temporary) ones."""
    files = (Path(here) / name for here, _, names in os.walk(folder) for name in names if not name.startswith(".") and name != LOCK_FILE)
    return any(path != stamp and not (path.suffix == ".json" and path.parent != folder and _is_stamp(path)) for path in files)


class RunFolder:
    """A folder of cached results made with one set of settings, owned by this process until :meth:`close`.

    Use it as a context manager (``with RunFolder(path) as folder:``) or call :meth:`close`;
    the lock is also dropped when the process ends, however it ends.

    Args:
        path: the folder (created if missing).
        settings: what the results depend on, JSON-able, without the key :data:`SOURCE_KEY`;
            the stamp adds this dvrk_gym's source fingerprint to them. None opens the folder
            without a stamp or any check (any caller may use its files).
        stamp: the name of the file holding the settings.

    Raises:
        RunFolderBusy: another process owns the folder.
        ValueError: the folder holds results and is stamped with other settings (the message
            lists them), or by another version of dvrk_gym (the message gives both fingerprints)
            or one whose stamps had no source fingerprint; its results and stamp are left as
            they were; but a folder with no file but stamps and locks (a run refused before it made
            anything) is stamped afresh, unless this process already owns it.
        OSError: the folder cannot be made or written (a file of that name, no permission).
    """

    def __init__(self, path: str | os.PathLike, settings: Mapping[str, Any] | None = None, stamp: str = "settings.json") -> None:
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise NotADirectoryError(f"{self.path} is a file, not a folder; give a folder for the run")
        self.stamp = self.path / stamp
        if settings is not None and self.path.is_dir() and not (self.path / LOCK_FILE).exists():  # no run's folder yet:
            # refused before a lock file is made in it (checked again under the lock, where a busy folder is named first)
            _refuse_unstamped_files(self.path, self.stamp)
        self.path.mkdir(parents=True, exist_ok=True)
        self.made_s: dict[str, float] = {}  # wall time of each result made (not loaded) by cached(), by stage, s
        self._lock = FileLock(self.path / LOCK_FILE, timeout=0, thread_local=False, is_singleton=True)
        self._held = False
        self._acquire()
        try:
            first_owner = self._lock.lock_counter == 1  # the first owner in this process: nobody else writes here now
            if first_owner:
                self._claim()
            if settings is not None:
                self._check_and_stamp(settings, first_owner)
            if first_owner:  # only in a folder taken as this run's: a refused one is left as it was
                remove_partial_files(self.path, skip_folders_with=LOCK_FILE)  # not inside another run's folder
        except BaseException:
            self.close()
            raise

    def _acquire(self) -> None:
        _lock_text(self.path / LOCK_FILE)  # a lock path that is no regular file (a FIFO would block) is refused first
        try:
            self._lock.acquire()
        except Timeout:
            owner = _owner_pid(_lock_text(self.path / LOCK_FILE))
            who = f"process {owner}" if owner is not None else "another process"
            raise RunFolderBusy(
                f"{self.path} is in use by {who} (its lock: {self.path / LOCK_FILE}); "
                "wait for that run to finish, stop it, or give another folder"
            ) from None
        self._held = True

    def _claim(self) -> None:
        """Write this process's id into the lock file just taken, first logging the dead owner it replaces."""
        lock_file = self.path / LOCK_FILE
        previous = _owner_pid(_lock_text(lock_file))
        if previous is not None and previous != os.getpid():
            logger.warning("%s: taking over the lock process %d left without releasing it (it was killed or crashed)", self.path, previous)
        # Written in place, not atomically: a rename would give the lock path a new inode, which another
        # process could lock while this one holds the old one.
        lock_file.write_text(json.dumps({"pid": os.getpid(), "since": time.strftime("%Y-%m-%d %H:%M:%S")}))

    def close(self) -> None:
        """Give up the folder (safe to call more than once); the lock file is emptied first, so
        the next owner knows it was released, not left by a dead process."""
        if not self._held:
            return
        self._held = False
        if self._lock.lock_counter == 1:
            with contextlib.suppress(OSError):
                (self.path / LOCK_FILE).write_text("")
        self._lock.release()

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "_held", False):
            with contextlib.suppress(Exception):  # at interpreter exit the kernel drops the lock anyway
                self.close()

    def _check_and_stamp(self, settings: Mapping[str, Any], first_owner: bool) -> None:
        wanted = json.loads(json.dumps(settings))  # tuples become lists, as they come back from the stamp
        if SOURCE_KEY in wanted:
            raise ValueError(f"{SOURCE_KEY!r} is reserved for the stamp's source fingerprint; give the setting another name")
        here = source_fingerprint()
        found = _read_stamp(self.stamp)
        if found is None:  # files already here were made with settings no stamp recorded: never taken as these
            _refuse_unstamped_files(self.path, self.stamp)
        else:
            try:
                _refuse_other_source(self.stamp, found.pop(SOURCE_KEY, None), here, RESUME_REMEDY)
                if found != wanted:
                    differences = "; ".join(settings_differences(found, wanted))
                    raise ValueError(
                        f"{self.path} holds a run with other settings ({differences}; see {self.stamp}); use another --out or delete it"
                    )
            except ValueError:  # taken all the same when a run was refused or stopped before it made anything
                if not first_owner or _holds_results(self.path, self.stamp):
                    raise
                logger.info("%s holds no results yet: it is stamped with this run's settings instead", self.path)
        atomic_write_json(self.stamp, {**wanted, SOURCE_KEY: here.to_json()}, indent=1, sort_keys=True)

    def file(self, name: str) -> Path:
        """The path of a result in the folder."""
        return self.path / name

    def has(self, name: str) -> bool:
        """Whether the folder holds the result ``name``."""
        return self.file(name).exists()

    def load(self, name: str, load: Callable[[Path], T]) -> T | None:
        """The result ``name`` read by ``load``; None when it is missing or unreadable.

        An unreadable file (``load`` raised one of :data:`UNREADABLE`, but not a permission
        error) is named in a warning and set aside as ``<name>.corrupt`` (``.corrupt.2`` beside an
        earlier one: :func:`~dvrk_gym.utils.atomic.set_aside`), so that it is made again.
        """
        path = self.file(name)
        if not path.exists():
            return None
        try:
            return load(path)
        except PermissionError:
            raise
        except UNREADABLE as error:
            aside = set_aside(path)
            logger.warning("%s is unreadable (%s: %s); moved it to %s and making it again", path, type(error).__name__, error, aside.name)
            return None

    def cached(
        self, name: str, *, make: Callable[[], T], load: Callable[[Path], T], save: Callable[[T, Path], Any], stage: str | None = None
    ) -> T:
        """The result ``name``: loaded from the folder if there and readable, else made, saved (atomically) and timed.

        Args:
            name: the result's file name in the folder.
            make: computes the result.
            load: reads the result from its path.
            save: writes the result to the path it is given (a temporary one, renamed into place).
            stage: the key of its time in :attr:`made_s` (default: the file name's stem).
        """
        path = self.file(name)
        found = self.load(name, load)
        if found is not None:
            logger.info("%s: loaded %s", stage or path.stem, path)
            return found
        start = time.perf_counter()
        value = make()
        self.made_s[stage or path.stem] = time.perf_counter() - start
        with atomic_path(path) as temporary:
            save(value, temporary)
        return value

    def read_json(self, name: str) -> Any:
        """A JSON result of the folder; None when it is missing or unreadable (see :meth:`load`)."""
        return self.load(name, read_json)

    def write_json(self, name: str, value: Any) -> Path:
        """Write a JSON result into the folder (indented, atomically); returns its path."""
        return atomic_write_json(self.file(name), value, indent=1)
