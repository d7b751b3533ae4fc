"""One way to write a file: all of it or none of it (and JSON read back within bounds).

Every file the package writes goes through here. The bytes go to a temporary file in the
same folder (``.<stem>.<random>.partial<suffix>``: the target's suffix is kept, so writers
that choose a format by it, such as matplotlib's ``savefig`` or ``np.savez``, behave as
with the target), are flushed and fsynced, and the temporary file is renamed over the
target with :func:`os.replace` (atomic within one file system); the folder is then fsynced
so that the rename survives a power cut. A kill at any moment leaves the old file or the
new one, never a half-written one; a temporary file left by a kill is removed by
:func:`remove_partial_files` (a :class:`~dvrk_gym.utils.run_folder.RunFolder` does so when
it is opened).

:func:`read_json` is the other way: a JSON file that may come from elsewhere (edited,
damaged, a device such as ``/dev/zero``, or far too large), read only when it is a regular
file of at most ``max_bytes``; a file that is not so, or not JSON, is a ``ValueError`` naming
it (a missing file a ``FileNotFoundError``, an unreadable one a ``PermissionError``).
"""

from __future__ import annotations

import collections
import contextlib
import hashlib
import json
import logging
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

logger = logging.getLogger(__name__)

PARTIAL_MARK = ".partial"
"""What the name of a temporary file holds before the target's suffix."""
CORRUPT_SUFFIX = ".corrupt"
"""What :func:`set_aside` adds to the name of a damaged file it keeps."""
MAX_SET_ASIDE = 1000
"""The most damaged copies of one file :func:`set_aside` keeps."""


def partial_path(path: str | os.PathLike) -> Path:
    """A fresh temporary path beside ``path``, hidden, with ``path``'s suffix."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{secrets.token_hex(4)}{PARTIAL_MARK}{path.suffix}")


def _fsync_path(path: Path, directory: bool = False) -> None:
    """Flush a file's (or a folder's) data to the disk; a no-op where a folder cannot be opened (Windows)."""
    try:
        descriptor = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0))
    except OSError:
        if directory:
            return
        raise
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path to write ``path`` through: renamed over ``path`` if the block ends well, removed if not.

    For writers that take a path (``savefig``, ``np.savez``, stable-baselines3's ``save``).

    Raises:
        OSError: the folder is missing or read-only, ``path`` is a folder, or the block wrote
            nothing; an error of the writing that names no file (a full disk) is raised again
            naming ``path``.
    """
    path = Path(path)
    temporary = partial_path(path)
    try:
        yield temporary
        if not temporary.is_file():
            raise OSError(f"nothing was written to {path}")
        _fsync_path(temporary)
        os.replace(temporary, path)
    except BaseException as error:
        with contextlib.suppress(OSError):
            temporary.unlink()
        if isinstance(error, OSError) and error.filename is None and error.errno is not None:
            raise OSError(error.errno, error.strerror, str(path)) from error  # "No space left on device: 'path'"
        raise
    _fsync_path(path.parent, directory=True)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb", encoding: str | None = None) -> Iterator[IO[Any]]:
    """A stream to write ``path`` through (``"wb"`` or ``"w"``), in place only if the block ends well.

    For writers that take a stream (``np.savez`` to a handle, ``torch.save``).
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"mode must be 'wb' or 'w', got {mode!r}")
    with atomic_path(path) as temporary, open(temporary, mode, encoding=encoding if "b" not in mode else None) as stream:
        yield stream
        stream.flush()


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path``, all or nothing; returns the path."""
    with atomic_open(path, "wb") as stream:
        stream.write(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path``, all or nothing; returns the path."""
    return atomic_write_bytes(path, text.encode(encoding))


MAX_JSON_BYTES = 16 * 2**20
"""The largest JSON file :func:`read_json` reads by default, bytes (the package's settings,
stamps, tables and results are kilobytes to a few megabytes)."""


def check_regular_file(path: str | os.PathLike, max_bytes: int, what: str, error: type[ValueError] = ValueError) -> int:
    """The size of ``path`` in bytes, once it is known to be a regular file of at most
    ``max_bytes``: a FIFO there would block a read, a device never end it, a folder cannot be
    read as one.

    Raises:
        FileNotFoundError: there is no such file.
        error: a folder or another file that is not a regular one ("PATH is a folder, not
            WHAT"), or larger than ``max_bytes`` ("PATH: N bytes; WHAT has at most M").
    """
    path = Path(path)
    if path.exists() and not path.is_file():
        raise error(f"{path} is {'a folder' if path.is_dir() else 'not a regular file'}, not {what}")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    size = path.stat().st_size
    if size > max_bytes:
        raise error(f"{path}: {size:,} bytes; {what} has at most {max_bytes:,}")
    return size


def read_bounded(path: str | os.PathLike, max_bytes: int, what: str) -> bytes:
    """The bytes of ``path``, read only if it is a regular file of at most ``max_bytes`` (a
    FIFO there would block the read, a device never end it), and no more than that should it
    grow while it is read.

    Raises:
        FileNotFoundError: there is no such file.
        PermissionError: it may not be read.
        ValueError: not a regular file, or larger than ``max_bytes`` (:func:`check_regular_file`).
    """
    path = Path(path)
    check_regular_file(path, max_bytes, what)
    with path.open("rb") as file:
        data = file.read(max_bytes + 1)  # the size again: the file may have grown since
    if len(data) > max_bytes:
        raise ValueError(f"{path}: more than {max_bytes:,} bytes; {what} has at most {max_bytes:,}")
    return data


def _object_without_repeats(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    found = dict(pairs)
    if len(found) != len(pairs):
        repeated = sorted(key for key, count in collections.Counter(key for key, _ in pairs).items() if count > 1)
        raise ValueError(f"an object names {repeated[:5]} more than once")
    return found


def file_sha256(path: str | os.PathLike, max_bytes: int, what: str) -> str:
    """The SHA-256 of ``path`` (hex), read in chunks after checking it is a regular file of at
    most ``max_bytes`` (:func:`check_regular_file`), reading no more than that should it grow meanwhile.

    Raises:
        ValueError: not such a file, or it grew past ``max_bytes`` while it was read.
    """
    check_regular_file(path, max_bytes, what)
    digest, read = hashlib.sha256(), 0
    with open(path, "rb") as file:
        for chunk in iter(lambda: file.read(2**20), b""):
            read += len(chunk)
            if read > max_bytes:
                raise ValueError(f"{path} grew past {max_bytes:,} bytes while it was read; {what} has at most that")
            digest.update(chunk)
    return digest.hexdigest()


def read_json(path: str | os.PathLike, max_bytes: int = MAX_JSON_BYTES) -> Any:
    """The JSON value in ``path``, read only if it is a regular file of at most ``max_bytes``.

    Raises:
        FileNotFoundError: there is no such file.
        PermissionError: it may not be read.
        ValueError: not a regular file, too large, not UTF-8, not JSON, nested too deeply, or
            an object naming a key twice (which of the two would count is the reader's guess);
            the message names the file.
    """
    data = read_bounded(path, max_bytes, "a JSON file read here")
    try:
        return json.loads(data.decode("utf-8"), object_pairs_hook=_object_without_repeats)
    except (ValueError, RecursionError) as error:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise ValueError(f"{path} is not valid JSON ({type(error).__name__}: {error})") from None


def atomic_write_json(path: str | os.PathLike, value: Any, **dumps_options: Any) -> Path:
    """Write ``value`` as JSON (``json.dumps(value, **dumps_options)``) to ``path``, all or nothing.

    The JSON is made before anything is written, so a value that cannot be written leaves ``path`` as it was.
    """
    return atomic_write_text(path, json.dumps(value, **dumps_options))


def remove_partial_files(folder: str | os.PathLike, skip_folders_with: str | None = None) -> list[Path]:
    """Remove the temporary files a killed write left in ``folder`` and the folders below it; returns them.

    Only call this on a folder no other process is writing (a run folder its owner holds).

    Args:
        folder: the folder.
        skip_folders_with: a file name (a run folder's lock) that marks a folder below
            ``folder`` as another run's, whose owner may be writing it: such folders are left alone.
    """
    removed = []
    for here, folders, files in os.walk(Path(folder)):
        if skip_folders_with is not None:
            folders[:] = [name for name in folders if not (Path(here) / name / skip_folders_with).exists()]
        for name in files:
            path = Path(here) / name
            if name.startswith(".") and PARTIAL_MARK in name and path.is_file():
                with contextlib.suppress(OSError):
                    path.unlink()
                    removed.append(path)
    if removed:
        logger.info("removed %d temporary file(s) left by an interrupted write in %s", len(removed), folder)
    return removed


def atomic_savefig(figure: Any, path: str | os.PathLike, **options: Any) -> Path:
    """``figure.savefig(path, **options)`` (a matplotlib figure), all or nothing; returns the path."""
    with atomic_path(path) as temporary:
        figure.savefig(temporary, **options)
    return Path(path)


def set_aside(path: str | os.PathLike) -> Path:
    """Move a damaged file (or whatever stands at ``path``) to the first free name of
    ``<name>.corrupt``, ``<name>.corrupt.2``, ... beside it, and give that name: every copy set
    aside is kept, and an earlier one (even a folder) never blocks the move.

    Raises:
        FileExistsError: :data:`MAX_SET_ASIDE` copies are there already (naming them, to delete).
    """
    path = Path(path)
    for number in range(1, MAX_SET_ASIDE + 1):
        aside = path.with_name(path.name + CORRUPT_SUFFIX + (f".{number}" if number > 1 else ""))
        if not os.path.lexists(aside):  # the caller owns the folder (a run folder's lock): no race for the name
            os.replace(path, aside)
            return aside
    raise FileExistsError(f"{MAX_SET_ASIDE} damaged copies of {path} are set aside already ({path.name}{CORRUPT_SUFFIX}*); delete them")
