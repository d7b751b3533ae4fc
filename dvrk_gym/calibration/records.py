"""Data sets as frozen dataclasses of arrays, saved as plain ``.npz`` (never pickles).

Reading bounds every size before anything is allocated: the archive's declared sizes
(:data:`DATA_FILE_LIMITS`, through :mod:`dvrk_gym.utils.bounded_zip`), and each ``.npy``
header's shape and dtype against the bytes that follow it; object (pickled) arrays are refused.
"""

from __future__ import annotations

import io
import math
from dataclasses import fields
from os import PathLike
from typing import Any, ClassVar, TypeVar, cast

import numpy as np

from dvrk_gym.utils.atomic import atomic_open
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, open_archive, read_member, read_npy_header

__all__ = ["DATA_FILE_LIMITS", "NUMERIC_KINDS", "ArrayRecord", "non_finite_rows", "parse_npy", "read_npz_arrays"]

DATA_FILE_LIMITS = ArchiveLimits(max_file_bytes=512 * 2**20, max_members=10_000, max_member_bytes=256 * 2**20, max_total_bytes=512 * 2**20)
"""What a data file may hold: 512 MiB on disk and inflated, 256 MiB an array, 10,000 arrays
(the paper's Phase I, 5,301 rows, takes about 0.5 MB)."""
NUMERIC_KINDS = "fiub"
"""The numpy dtype kinds a data file's arrays may have: float, signed and unsigned integer, bool."""
_Record = TypeVar("_Record", bound="ArrayRecord")


def parse_npy(where: str, data: bytes, *, kinds: str = NUMERIC_KINDS) -> np.ndarray:
    """An ``.npy`` file's array parsed from its bytes: the header's shape and dtype are checked
    against the bytes actually there before any array is made.

    Args:
        where: names the bytes in an error (a file, or a file's member).
        data: the whole ``.npy`` file.
        kinds: the numpy dtype kinds accepted (objects, which would be pickles, never are).

    Raises:
        ValueError: no valid header, another dtype kind, or a header that does not fit the bytes.
    """
    stream = io.BytesIO(data)
    shape, fortran_order, dtype = read_npy_header(stream, where)
    if dtype.hasobject or dtype.kind not in kinds:
        raise ValueError(f"{where} has dtype {dtype}; only arrays of the kinds {kinds!r} are read (never pickles)")
    count = math.prod(shape)
    held = len(data) - stream.tell()
    if count * dtype.itemsize != held:
        raise ValueError(f"{where} declares {shape} {dtype} ({count * dtype.itemsize:,} bytes) but holds {held:,} bytes")
    array = np.frombuffer(data, dtype=dtype, count=count, offset=stream.tell())
    return array.reshape(shape, order="F" if fortran_order else "C").copy()


def read_npz_arrays(source: str | PathLike | bytes, *, where: str | None = None, kinds: str = NUMERIC_KINDS) -> dict[str, np.ndarray]:
    """Every array of an ``.npz``, read within :data:`DATA_FILE_LIMITS` (sizes checked before anything is inflated).

    Args:
        source: the file, or its bytes.
        where: names it in an error (default: the path; "archive in memory" for bytes).
        kinds: the numpy dtype kinds its arrays may have (:func:`parse_npy`).

    Raises:
        ValueError: no such file, not a zip within the limits, a member that is not an
            ``.npy`` array of ``kinds``, or a header that does not fit its bytes.
    """
    name = where or ("archive in memory" if isinstance(source, bytes) else str(source))
    try:
        with open_archive(source, DATA_FILE_LIMITS) as archive:
            arrays = {}
            for member in archive.namelist():
                if not member.endswith(".npy"):
                    raise ValueError(f"{name}: member {member!r} is not an .npy array")
                data = read_member(archive, member, DATA_FILE_LIMITS)
                arrays[member[: -len(".npy")]] = parse_npy(f"{name}: member {member!r}", data, kinds=kinds)
            return arrays
    except FileNotFoundError:
        raise ValueError(f"{name}: no such file") from None
    except ArchiveLimitError as error:
        raise ValueError(f"not an .npz file within the size limits: {error}") from None


def non_finite_rows(name: str, rows: np.ndarray) -> str | None:
    """What :meth:`ArrayRecord.value_problem` says of an (N, k) array with rows that are not
    all finite (how many, and the first), or None."""
    bad = np.flatnonzero(~np.isfinite(rows).all(axis=1))
    return f"{name} is not finite in {bad.size} rows (the first: {rows[bad[0]].tolist()})" if bad.size else None


class ArrayRecord:
    """Mixin for a frozen dataclass whose fields are all numpy arrays of equal length.

    A subclass states each field's row shape and kind in :attr:`ROW_LAYOUT`, which
    :meth:`load` checks: a file whose arrays are of other shapes, kinds or lengths is refused
    before any of it is used (an index array of floats, or one row short, would otherwise
    fail far from the file, or pick the wrong rows silently).
    """

    ROW_LAYOUT: ClassVar[dict[str, tuple[tuple[int, ...], str]]] = {}
    """Field -> (the shape of one row, e.g. ``(3,)`` or ``()``; the numpy dtype kinds allowed,
    e.g. ``"f"`` floats, ``"iu"`` ints, ``"b"`` bools)."""

    def save(self, path: str | PathLike) -> None:
        """Write every field to an ``.npz`` file at exactly ``path`` (no suffix added), atomically."""
        with atomic_open(path) as stream:
            np.savez(stream, **{f.name: getattr(self, f.name) for f in fields(cast(Any, self))})

    @classmethod
    def load(cls: type[_Record], path: str | PathLike) -> _Record:
        """Read a file written by :meth:`save`; refuse files of another kind or with pickles.

        Raises:
            ValueError: not a readable ``.npz`` of exactly this record's arrays, or an array of
                another row shape, kind or length than :attr:`ROW_LAYOUT` says (the message
                names the file and the array).
        """
        names = {f.name for f in fields(cast(Any, cls))}
        try:
            data = read_npz_arrays(path)
        except ValueError as error:
            raise ValueError(f"{path} is not a readable {cls.__name__} file: {error}") from None
        if set(data) != names:
            raise ValueError(f"{path} is not {cls.__name__} data: arrays {sorted(data)}, expected {sorted(names)}")
        rows = {len(array) if array.ndim else -1 for array in data.values()}
        for name, (row_shape, kinds) in cls.ROW_LAYOUT.items():
            array = data[name]
            if array.ndim != 1 + len(row_shape) or array.shape[1:] != row_shape or array.dtype.kind not in kinds:
                raise ValueError(
                    f"{path}: array {name!r} is {array.dtype}{list(array.shape)}; {cls.__name__} wants "
                    f"(N, {', '.join(map(str, row_shape))}) of dtype kind {kinds!r}".replace(", )", ")")
                )
        if len(rows) != 1:
            raise ValueError(f"{path}: {cls.__name__}'s arrays must have one row per sample, got lengths {sorted(rows)}")
        problem = cls.value_problem(data)
        if problem is not None:
            raise ValueError(f"{path} is not usable {cls.__name__} data: {problem}")
        return cls(**{name: data[name] for name in names})

    @classmethod
    def value_problem(cls, data: dict[str, np.ndarray]) -> str | None:
        """What is wrong with the values of arrays whose shapes and kinds :meth:`load` has
        checked (a subclass states its rules: rows that must be finite, say), or None."""
        return None
