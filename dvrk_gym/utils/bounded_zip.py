"""Zip archives from elsewhere, read within fixed size limits.

A zip's central directory declares each member's size, and a member of a few kilobytes can
inflate to gigabytes. :func:`open_archive` refuses an archive whose members, or whose
declared sizes, exceed :class:`ArchiveLimits` before anything is inflated, and
:func:`read_member` reads a member in chunks and stops as soon as it holds more than it
declared or than the limit allows. Model files, the skops archives inside them, data
records (``.npz``) and agent files (stable-baselines3's ``.zip``) are read through here.
"""

from __future__ import annotations

import io
import math
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from dvrk_gym.utils.atomic import check_regular_file

MIB = 2**20
_CHUNK_BYTES = MIB
NPY_MAX_HEADER_BYTES = 10_000
"""The longest ``.npy`` header read (numpy's own default limit)."""


class ArchiveLimitError(ValueError):
    """An archive is not a zip, or is larger than the limits allow (the message names the file and the limit)."""


@dataclass(frozen=True)
class ArchiveLimits:
    """What an archive may hold.

    Attributes:
        max_file_bytes: the archive file's size on disk, bytes.
        max_members: how many members it may list.
        max_member_bytes: one member's size once inflated, bytes.
        max_total_bytes: all members' sizes once inflated, together, bytes.
    """

    max_file_bytes: int = 512 * MIB
    max_members: int = 10_000
    max_member_bytes: int = 256 * MIB
    max_total_bytes: int = 512 * MIB


def open_archive(source: str | os.PathLike | bytes, limits: ArchiveLimits = ArchiveLimits()) -> zipfile.ZipFile:
    """Open a zip archive, a file or bytes in memory, whose declared sizes are all within ``limits`` (close it after use).

    Raises:
        FileNotFoundError: no such file.
        PermissionError: this process may not read it.
        ArchiveLimitError: not a zip archive, or larger than the limits.
    """
    opened: io.BytesIO | Path
    if isinstance(source, bytes):
        name, opened = "archive in memory", io.BytesIO(source)
        if len(source) > limits.max_file_bytes:
            raise ArchiveLimitError(f"{name}: {len(source):,} bytes; a zip archive has at most {limits.max_file_bytes:,}")
    else:
        path = Path(source)
        check_regular_file(path, limits.max_file_bytes, "a zip archive", ArchiveLimitError)
        name, opened = str(path), path
    try:
        archive = zipfile.ZipFile(opened)
    except PermissionError:  # the file may be whole: the caller must not take it for a damaged one
        raise
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as error:
        raise ArchiveLimitError(f"{name}: not a readable zip archive ({error})") from None
    try:
        _check_declared_sizes(name, archive.infolist(), limits)
    except BaseException:
        archive.close()
        raise
    return archive


def _check_declared_sizes(name: str, members: list[zipfile.ZipInfo], limits: ArchiveLimits) -> None:
    if len(members) > limits.max_members:
        raise ArchiveLimitError(f"{name}: {len(members):,} members; at most {limits.max_members:,} are read")
    for member in members:
        if member.flag_bits & 0x1:  # zipfile would ask for a password (RuntimeError) when it is read
            raise ArchiveLimitError(f"{name}: member {member.filename!r} is marked encrypted; the package writes no encrypted members")
        if member.file_size > limits.max_member_bytes:
            raise ArchiveLimitError(
                f"{name}: member {member.filename!r} inflates to {member.file_size:,} bytes "
                f"({member.compress_size:,} compressed); at most {limits.max_member_bytes:,} are read"
            )
    total = sum(member.file_size for member in members)
    if total > limits.max_total_bytes:
        raise ArchiveLimitError(f"{name}: members inflate to {total:,} bytes together; at most {limits.max_total_bytes:,} are read")


def read_member(archive: zipfile.ZipFile, name: str, limits: ArchiveLimits = ArchiveLimits()) -> bytes:
    """The bytes of member ``name``, read in chunks, refused once they exceed the declared size or the limit.

    Raises:
        KeyError: no such member.
        ArchiveLimitError: the member inflates beyond its declared size or the limit, or is corrupt.
    """
    info = archive.getinfo(name)
    source = archive.filename or "archive in memory"
    allowed = min(info.file_size, limits.max_member_bytes)
    chunks, total = [], 0
    try:
        with archive.open(info) as stream:
            while chunk := stream.read(min(_CHUNK_BYTES, allowed + 1 - total)):
                total += len(chunk)
                if total > allowed:
                    raise ArchiveLimitError(f"{source}: member {name!r} inflates beyond its declared {info.file_size:,} bytes")
                chunks.append(chunk)
    except (zipfile.BadZipFile, OSError, EOFError, NotImplementedError, ValueError, RuntimeError) as error:
        if isinstance(error, ArchiveLimitError):
            raise
        raise ArchiveLimitError(f"{source}: member {name!r} is corrupt ({type(error).__name__}: {error})") from None
    return b"".join(chunks)


def read_npy_header(stream: BinaryIO, where: str) -> tuple[tuple[int, ...], bool, np.dtype]:
    """The shape, Fortran order and dtype an ``.npy`` stream's header declares (the stream is left after it).

    Raises:
        ValueError: no valid header of format 1.0 or 2.0 within ``NPY_MAX_HEADER_BYTES`` (``where`` names it).
    """
    try:
        version = np.lib.format.read_magic(stream)
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f"npy format version {version}; expected 1.0 or 2.0")
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran_order, dtype = read_header(stream, max_header_size=NPY_MAX_HEADER_BYTES)
    except (ValueError, SyntaxError, TypeError, EOFError) as error:
        raise ValueError(f"{where} has no valid npy header: {error}") from None
    return tuple(int(n) for n in shape), bool(fortran_order), dtype


def check_npy_members(archive: zipfile.ZipFile) -> None:
    """Refuse an archive with an ``.npy`` member whose header declares other than the bytes the
    member holds, or objects (pickles): numpy allocates what a header declares before it reads
    the data, so a header of 2**31 elements in a file of kilobytes reserved 16 GiB. Only each
    header is inflated.

    Raises:
        ArchiveLimitError: such a member (the message names it).
    """
    source = archive.filename or "archive in memory"
    for info in archive.infolist():
        if not info.filename.endswith(".npy"):
            continue
        where = f"{source}: member {info.filename!r}"
        try:
            with archive.open(info) as stream:
                head = io.BytesIO(stream.read(NPY_MAX_HEADER_BYTES + 64))
            shape, _, dtype = read_npy_header(head, where)
        except (zipfile.BadZipFile, OSError, EOFError, NotImplementedError, ValueError, RuntimeError) as error:
            raise ArchiveLimitError(str(error) if str(error).startswith(where) else f"{where} is corrupt ({error})") from None
        if dtype.hasobject:
            raise ArchiveLimitError(f"{where} holds objects ({dtype}); no pickle is read")
        declared, held = math.prod(shape) * dtype.itemsize, info.file_size - head.tell()
        if declared != held:
            raise ArchiveLimitError(f"{where} declares {shape} {dtype} ({declared:,} bytes) but holds {held:,} bytes")
