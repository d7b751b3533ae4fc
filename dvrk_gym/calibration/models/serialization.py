"""Model files that cannot run code when loaded: plain ``.npz`` with a JSON header and digest.

A model file is an ``np.savez`` archive holding

- the model's numeric arrays (float, integer or bool; never object arrays),
- ``__metadata__``: a 0-d unicode array with JSON ``{"kind", "format_version", "params",
  "arrays": {name: {"shape", "dtype"}}}``,
- ``__digest__``: a 0-d unicode array, the SHA-256 (hex) of the metadata and every array.

Loading never unpickles and never trusts a size it has not checked: the archive's declared
and actual sizes are bounded (:data:`MODEL_FILE_LIMITS`, through
:mod:`dvrk_gym.utils.bounded_zip`), each ``.npy`` header's shape and dtype must match the
bytes that follow before an array is made, and anything that is not exactly such a file is
refused with ``ModelFileError``. The digest detects corruption and careless edits; it is
not a signature (anyone can recompute it), so the models also check their parameters
against fixed bounds and their arrays' shapes before building anything, and their arrays'
finiteness and index ranges after.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
from collections.abc import Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from dvrk_gym.utils.atomic import atomic_open
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, open_archive, read_member

__all__ = [
    "FORMAT_VERSION",
    "MODEL_FILE_LIMITS",
    "ModelFileError",
    "SavableModel",
    "read_arrays",
    "read_model_file",
    "require_array",
    "require_names",
    "write_model_file",
]

FORMAT_VERSION = 1
_METADATA = "__metadata__"
_DIGEST = "__digest__"
_ALLOWED_KINDS = "fiub"  # float, signed and unsigned integer, bool
_MAX_NPY_HEADER_BYTES = 10_000
MODEL_FILE_LIMITS = ArchiveLimits(max_file_bytes=512 * 2**20, max_members=10_000, max_member_bytes=256 * 2**20, max_total_bytes=512 * 2**20)
"""What a model file may hold: 512 MiB on disk and inflated, 256 MiB per array, 10,000 arrays
(the largest model here, a 100-tree forest on the paper's 1,939 rows, takes about 10 MB)."""

PathLike = str | os.PathLike
_Model = TypeVar("_Model", bound="SavableModel")


class ModelFileError(ValueError):
    """A model file is missing, corrupt, tampered with or of the wrong kind."""


def _digest(metadata_json: str, arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 over the metadata and each array's name, dtype, shape and bytes, in name order."""
    sha = hashlib.sha256()

    def update(chunk: bytes) -> None:
        sha.update(len(chunk).to_bytes(8, "little"))  # length prefix: no ambiguous joins
        sha.update(chunk)

    update(metadata_json.encode("utf-8"))
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        update(name.encode("utf-8"))
        update(array.dtype.str.encode("ascii"))
        update(json.dumps(list(array.shape)).encode("ascii"))
        update(array.tobytes())
    return sha.hexdigest()


def write_model_file(path: PathLike, kind: str, params: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> None:
    """Write a model file.

    Args:
        path: Destination file, written exactly there (``.npz`` is the customary suffix).
        kind: Model kind, checked on load.
        params: JSON-serialisable hyper-parameters.
        arrays: Numeric arrays by name (names must not start with ``__``).

    Raises:
        ValueError: If an array is not numeric or a name is reserved.
    """
    arrays = {name: np.ascontiguousarray(value) for name, value in arrays.items()}
    for name, value in arrays.items():
        if name.startswith("__") or value.dtype.kind not in _ALLOWED_KINDS:
            raise ValueError(
                f"array {name!r} ({value.dtype}) cannot be saved: names must not start with '__' and dtypes must be numeric or bool"
            )
    metadata = {
        "kind": kind,
        "format_version": FORMAT_VERSION,
        "params": dict(params),
        "arrays": {name: {"shape": list(value.shape), "dtype": value.dtype.str} for name, value in sorted(arrays.items())},
    }
    metadata_json = json.dumps(metadata, sort_keys=True)
    with atomic_open(path) as stream:  # a handle, so np.savez adds no ".npz" to the name
        entries: dict[str, Any] = {**arrays, _METADATA: np.array(metadata_json), _DIGEST: np.array(_digest(metadata_json, arrays))}
        np.savez(stream, **entries)


def _npy_array(path: PathLike, name: str, data: bytes) -> np.ndarray:
    """One ``.npy`` member parsed from its bytes: the header's shape and dtype are checked
    against the bytes actually there before any array is made."""
    stream = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(stream)
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f"npy format version {version}; expected 1.0 or 2.0")
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran_order, dtype = read_header(stream, max_header_size=_MAX_NPY_HEADER_BYTES)
    except (ValueError, SyntaxError, TypeError, EOFError) as error:
        raise ModelFileError(f"{path}: member {name!r} has no valid npy header: {error}") from None
    if dtype.hasobject or dtype.kind not in _ALLOWED_KINDS + "U":
        raise ModelFileError(f"{path}: member {name!r} has dtype {dtype}; only numeric, bool and string arrays are read (never pickles)")
    count = math.prod(shape)
    held = len(data) - stream.tell()
    if count * dtype.itemsize != held:
        raise ModelFileError(
            f"{path}: member {name!r} declares {shape} {dtype} ({count * dtype.itemsize:,} bytes) but holds {held:,} bytes"
        )
    array = np.frombuffer(data, dtype=dtype, count=count, offset=stream.tell())
    return array.reshape(shape, order="F" if fortran_order else "C").copy()


def read_arrays(path: PathLike) -> dict[str, np.ndarray]:
    """Every array of an ``.npz``, read within :data:`MODEL_FILE_LIMITS` (sizes checked before anything is inflated)."""
    if not os.path.isfile(path):
        raise ModelFileError(f"{path}: no such model file")
    try:
        with open_archive(path, MODEL_FILE_LIMITS) as archive:
            arrays = {}
            for member in archive.namelist():
                if not member.endswith(".npy"):
                    raise ModelFileError(f"{path}: member {member!r} is not an .npy array")
                arrays[member[: -len(".npy")]] = _npy_array(path, member, read_member(archive, member, MODEL_FILE_LIMITS))
            return arrays
    except ArchiveLimitError as error:
        raise ModelFileError(f"not an .npz file within the size limits: {error}") from None


def _string(arrays: Mapping[str, np.ndarray], name: str, path: PathLike) -> str:
    value = arrays.get(name)
    if value is None:
        raise ModelFileError(f"{path}: missing {name!r}; not a dvrk_gym model file")
    if value.shape != () or value.dtype.kind != "U":
        raise ModelFileError(f"{path}: {name!r} is {value.dtype} {value.shape}; expected a string")
    return str(value)


def _check_declared(path: PathLike, declared: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> None:
    missing = sorted(set(declared) - set(arrays))
    extra = sorted(set(arrays) - set(declared))
    if missing or extra:
        raise ModelFileError(f"{path}: arrays do not match the metadata: missing {missing}, unexpected {extra}")
    for name, spec in declared.items():
        if not isinstance(spec, dict):
            raise ModelFileError(f"{path}: metadata for array {name!r} is not an object")
        array = arrays[name]
        if list(array.shape) != spec.get("shape") or array.dtype.str != spec.get("dtype"):
            raise ModelFileError(
                f"{path}: array {name!r} is {array.dtype.str} {list(array.shape)}; metadata says {spec.get('dtype')} {spec.get('shape')}"
            )
        if array.dtype.kind not in _ALLOWED_KINDS:
            raise ModelFileError(f"{path}: array {name!r} has dtype {array.dtype}; expected numeric or bool")
        if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
            raise ModelFileError(f"{path}: array {name!r} holds non-finite values")


def read_model_file(path: PathLike, kind: str) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read and verify a model file written by :func:`write_model_file`.

    Args:
        path: The ``.npz`` file.
        kind: The model kind the caller expects.

    Returns:
        ``(params, arrays)``: the hyper-parameters and the numeric arrays by name.

    Raises:
        ModelFileError: If the file is not a zip/npz, holds object (pickled) arrays, has a
            bad or missing header, the wrong kind or version, missing or extra arrays,
            shapes or dtypes unlike the header, non-finite floats, or a digest mismatch.
    """
    arrays = read_arrays(path)
    metadata_json = _string(arrays, _METADATA, path)
    digest = _string(arrays, _DIGEST, path)
    data = {name: value for name, value in arrays.items() if name not in (_METADATA, _DIGEST)}
    try:
        metadata = json.loads(metadata_json)
    except (json.JSONDecodeError, RecursionError) as error:
        raise ModelFileError(f"{path}: metadata is not valid JSON: {error}") from None
    if not isinstance(metadata, dict) or not isinstance(metadata.get("arrays"), dict) or not isinstance(metadata.get("params"), dict):
        raise ModelFileError(f"{path}: metadata lacks 'params' and 'arrays' objects")
    if metadata.get("kind") != kind:
        raise ModelFileError(f"{path}: holds a {metadata.get('kind')!r} model; expected {kind!r}")
    if metadata.get("format_version") != FORMAT_VERSION:
        raise ModelFileError(f"{path}: format version {metadata.get('format_version')!r}; this dvrk_gym reads version {FORMAT_VERSION}")
    _check_declared(path, metadata["arrays"], data)
    if _digest(metadata_json, data) != digest:
        raise ModelFileError(f"{path}: SHA-256 digest mismatch: the file is corrupt or was edited")
    return metadata["params"], data


def require_array(arrays: Mapping[str, np.ndarray], name: str, shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
    """An array of a model file with an exact shape and dtype, else ``ValueError``."""
    if name not in arrays:
        raise ValueError(f"missing array {name!r}")
    array = arrays[name]
    if array.shape != tuple(shape) or array.dtype != np.dtype(dtype):
        raise ValueError(f"array {name!r} is {array.dtype} {array.shape}; expected {np.dtype(dtype)} {tuple(shape)}")
    return array


def require_names(arrays: Mapping[str, np.ndarray], names: set[str] | frozenset[str]) -> None:
    """Raise ``ValueError`` unless the file holds exactly the arrays ``names``."""
    missing, extra = sorted(set(names) - set(arrays)), sorted(set(arrays) - set(names))
    if missing or extra:
        raise ValueError(f"arrays do not fit the parameters: missing {missing}, unexpected {extra}")


class SavableModel:
    """Mixin: ``save``/``load`` through :func:`write_model_file` and :func:`read_model_file`.

    Subclasses set ``KIND`` and implement ``_export`` and ``_restore``. ``_restore`` raises
    ``ValueError`` (or ``KeyError``) on arrays that do not fit the parameters; ``load`` turns
    those into ``ModelFileError`` naming the file.
    """

    KIND: ClassVar[str] = ""

    def _export(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        raise NotImplementedError

    @classmethod
    def _restore(cls: type[_Model], params: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> _Model:
        raise NotImplementedError

    def save(self, path: PathLike) -> None:
        """Save the fitted model to ``path`` (an ``.npz`` file; no pickle)."""
        params, arrays = self._export()
        write_model_file(path, self.KIND, params, arrays)

    @classmethod
    def load(cls: type[_Model], path: PathLike) -> _Model:
        """Load a model saved by ``save``; raises ``ModelFileError`` on any bad file."""
        params, arrays = read_model_file(path, cls.KIND)
        try:
            return cls._restore(params, arrays)
        except (ValueError, KeyError, TypeError, AttributeError, OverflowError) as error:
            if isinstance(error, ModelFileError):
                raise
            raise ModelFileError(f"{path}: invalid {cls.KIND} model: {error}") from None
