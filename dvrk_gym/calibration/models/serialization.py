"""Model files from well-kept libraries: a zip of a small JSON, safetensors arrays and skops estimators.

A model file (a ``.zip``; members stored uncompressed, with fixed timestamps) holds

- ``model.json``: the format and its version, the model's kind, its parameters, its feature
  layout and units (:meth:`SavableModel.layout`), each array's shape and dtype, each other
  member's size in bytes and SHA-256, and the versions of the libraries that wrote it;
- ``arrays.safetensors``: the numeric arrays (network weights, scalers, rotations...), written
  and read by ``safetensors`` (absent when the model has none);
- ``<name>.skops``: scikit-learn estimators (the random forests), written by ``skops.io`` and
  read back only as the types of the model's explicit trusted list
  (:mod:`dvrk_gym.utils.estimator_files`).

Nothing is unpickled, and nothing is read before its size is bounded: the archive's declared
sizes first (:data:`MODEL_FILE_LIMITS`), then ``model.json`` (at most :data:`MAX_MANIFEST_BYTES`),
whose parameters the model checks against fixed bounds (a network's layers and units, a
forest's trees) before any other member is read; each member must have the size ``model.json``
gives it, and then its SHA-256. safetensors refuses a header whose shapes do not fit its bytes;
the arrays must have the declared shapes and dtypes and be finite, and the models check the
rest (a tree's child indices, a rotation's orthogonality). The SHA-256 finds corruption and
careless edits; it is no signature (anyone can recompute it), hence those checks.

Files of the retired format (an ``.npz`` of arrays with a JSON header, version 1) are refused
with the command that makes them again.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, ClassVar, TypeVar

import numpy as np
import safetensors.numpy
from safetensors import SafetensorError

from dvrk_gym.calibration.records import NUMERIC_KINDS
from dvrk_gym.utils.atomic import atomic_open
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, open_archive, read_member
from dvrk_gym.utils.estimator_files import EstimatorFileError, dump_estimator, load_estimator

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MODEL_FILE_LIMITS",
    "ModelFileError",
    "ModelParts",
    "SavableModel",
    "require_array",
    "require_names",
    "retired_format_message",
    "write_model_file",
]

FORMAT = "dvrk_gym.model"
FORMAT_VERSION = 2
"""The format's name and version in ``model.json`` (version 1 was the retired ``.npz``)."""
MANIFEST = "model.json"
ARRAYS = "arrays.safetensors"
ESTIMATOR_SUFFIX = ".skops"
MAX_MANIFEST_BYTES = 2**20
MODEL_FILE_LIMITS = ArchiveLimits(max_file_bytes=512 * 2**20, max_members=64, max_member_bytes=256 * 2**20, max_total_bytes=512 * 2**20)
"""What a model file may hold: 512 MiB, 256 MiB a member, 64 members (the largest model here,
the two-phase calibrator, has seven: its JSON, its arrays and five forests, 2 MB in all)."""
RETIRED_MARKER = "__metadata__.npy"
"""The member by which a file of the retired ``.npz`` format is recognised."""
_NAME = re.compile(r"[A-Za-z0-9_.+-]{1,100}")
_FIXED_TIME = (1980, 1, 1, 0, 0, 0)  # the zip epoch: the same model gives the same outer archive
_LIBRARIES = ("numpy", "scikit-learn", "skops", "safetensors")  # their versions are written, for the record (not checked)

PathLike = str | os.PathLike
_Model = TypeVar("_Model", bound="SavableModel")


class ModelFileError(ValueError):
    """A model file is missing, corrupt, tampered with, of the wrong kind or of a retired format."""


@dataclass
class ModelParts:
    """What a model file holds besides its JSON: the parameters, numeric arrays and scikit-learn estimators.

    Attributes:
        params: JSON-serialisable hyper-parameters.
        arrays: numeric (float, integer, bool) arrays by name.
        estimators: scikit-learn estimators by name.
    """

    params: dict[str, Any]
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    estimators: dict[str, Any] = field(default_factory=dict)

    def prefixed(self, prefix: str) -> ModelParts:
        """The arrays and estimators with ``prefix`` before each name (for a model made of models)."""
        return ModelParts(self.params, {prefix + k: v for k, v in self.arrays.items()}, {prefix + k: v for k, v in self.estimators.items()})

    def part(self, prefix: str, params: Any) -> ModelParts:
        """The arrays and estimators named ``prefix...``, without the prefix, with ``params``."""

        def strip(items: Mapping[str, Any]) -> dict[str, Any]:
            return {name[len(prefix) :]: value for name, value in items.items() if name.startswith(prefix)}

        return ModelParts(dict(params), strip(self.arrays), strip(self.estimators))


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _encode_members(parts: ModelParts) -> tuple[dict[str, bytes], dict[str, Any]]:
    """The members' bytes, and the arrays' shapes and dtypes for ``model.json``."""
    arrays = {name: np.ascontiguousarray(value) for name, value in sorted(parts.arrays.items())}
    for name, value in arrays.items():
        if not _NAME.fullmatch(name) or value.dtype.kind not in NUMERIC_KINDS:
            raise ValueError(f"array {name!r} ({value.dtype}) cannot be saved: names match {_NAME.pattern}, dtypes are numeric or bool")
    members = {ARRAYS: safetensors.numpy.save(arrays)} if arrays else {}
    for name, estimator in sorted(parts.estimators.items()):
        if not _NAME.fullmatch(name):
            raise ValueError(f"estimator name {name!r} does not match {_NAME.pattern}")
        members[name + ESTIMATOR_SUFFIX] = dump_estimator(estimator)
    shapes = {name: {"shape": list(value.shape), "dtype": value.dtype.name} for name, value in arrays.items()}
    return members, shapes


def write_model_file(path: PathLike, kind: str, layout: Mapping[str, Any], parts: ModelParts) -> None:
    """Write a model file at exactly ``path``, atomically.

    Args:
        path: destination (``.zip`` is the customary suffix).
        kind: the model kind, checked on load.
        layout: its inputs and outputs with their units, checked on load.
        parts: its parameters, arrays and estimators.

    Raises:
        ValueError: an array that is not numeric, or a name outside ``[A-Za-z0-9_.+-]``.
    """
    members, shapes = _encode_members(parts)
    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "layout": dict(layout),
        "params": dict(parts.params),
        "arrays": shapes,
        "members": {name: {"bytes": len(data), "sha256": _sha256(data)} for name, data in members.items()},
        "written_with": {name: metadata.version(name) for name in _LIBRARIES},
    }
    entries = {MANIFEST: json.dumps(manifest, indent=1, sort_keys=True).encode("utf-8"), **members}
    with atomic_open(path) as stream, zipfile.ZipFile(stream, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, data in entries.items():
            info = zipfile.ZipInfo(name, date_time=_FIXED_TIME)
            info.external_attr = 0o644 << 16  # rw-r--r-- when unzipped
            archive.writestr(info, data)


def retired_format_message(path: PathLike) -> str:
    """What to do with a model file of the retired ``.npz`` format."""
    return (
        f"{path} is a model file of dvrk_gym's retired .npz format (version 1), which this version no longer "
        "reads (models are now files of skops and safetensors). Make the calibration run again in a new folder: "
        f"`dvrk-gym calibrate --out NEW_FOLDER` with the settings in {os.path.join(os.path.dirname(path) or '.', 'pipeline_config.json')} "
        "(that folder's cached Phase I and II data were made by an older dvrk_gym, whose run folders this version "
        "does not resume); a model of your own, fit it again and save it."
    )


class _ModelArchive:
    """An opened model file whose ``model.json`` is read and checked; members are read on demand."""

    def __init__(self, path: PathLike, kind: str) -> None:
        self.path = path
        if not os.path.isfile(path):
            found = "no such model file" if not os.path.exists(path) else "a folder" if os.path.isdir(path) else "not a regular file"
            raise ModelFileError(f"{path}: {found}" + ("" if found.startswith("no such") else ", not a model file"))
        try:
            self.archive = open_archive(path, MODEL_FILE_LIMITS)
        except ArchiveLimitError as error:
            raise ModelFileError(f"not a model file within the size limits: {error}") from None
        try:
            self.manifest = self._read_manifest(kind)
            self._check_members()
        except BaseException:
            self.archive.close()
            raise

    def __enter__(self) -> _ModelArchive:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.archive.close()

    def _read(self, name: str, limit: int) -> bytes:
        try:
            return read_member(self.archive, name, ArchiveLimits(max_member_bytes=limit))
        except ArchiveLimitError as error:
            raise ModelFileError(f"{self.path}: {error}") from None

    def _read_manifest(self, kind: str) -> dict[str, Any]:
        names = self.archive.namelist()
        if MANIFEST not in names:
            if RETIRED_MARKER in names:
                raise ModelFileError(retired_format_message(self.path))
            raise ModelFileError(f"{self.path}: no {MANIFEST}; not a dvrk_gym model file")
        try:
            manifest = json.loads(self._read(MANIFEST, MAX_MANIFEST_BYTES))
        except (ValueError, RecursionError) as error:
            raise ModelFileError(f"{self.path}: {MANIFEST} is not valid JSON: {str(error)[:200]}") from None
        if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
            raise ModelFileError(f"{self.path}: {MANIFEST} is not a {FORMAT} manifest")
        if manifest.get("format_version") != FORMAT_VERSION:
            version = manifest.get("format_version")
            raise ModelFileError(f"{self.path}: format version {version!r}; this dvrk_gym reads version {FORMAT_VERSION}")
        if manifest.get("kind") != kind:
            raise ModelFileError(f"{self.path}: holds a {manifest.get('kind')!r} model; expected {kind!r}")
        for key in ("params", "layout", "arrays", "members"):
            if not isinstance(manifest.get(key), dict):
                raise ModelFileError(f"{self.path}: {MANIFEST} lacks the object {key!r}")
        return manifest

    def _check_members(self) -> None:
        """The archive holds exactly the declared members, each of its declared size (before any is read)."""
        declared = self.manifest["members"]
        found = sorted(set(self.archive.namelist()) - {MANIFEST})
        if found != sorted(declared) or len(self.archive.namelist()) != len(found) + 1:
            raise ModelFileError(f"{self.path}: members {found} do not match {MANIFEST}'s {sorted(declared)}")
        unknown = sorted(name for name in declared if name != ARRAYS and not name.endswith(ESTIMATOR_SUFFIX))
        if unknown or (ARRAYS in declared) != bool(self.manifest["arrays"]):
            raise ModelFileError(
                f"{self.path}: unexpected members {unknown}: a model file holds {ARRAYS} (if it declares arrays) and .skops estimators"
            )
        for name, spec in declared.items():
            size = spec.get("bytes") if isinstance(spec, dict) else None
            if not isinstance(size, int) or self.archive.getinfo(name).file_size != size:
                raise ModelFileError(
                    f"{self.path}: member {name!r} holds {self.archive.getinfo(name).file_size:,} bytes; the manifest says {size}"
                )
        for name, spec in self.manifest["arrays"].items():
            shape = spec.get("shape") if isinstance(spec, dict) else None
            if not isinstance(shape, list) or not all(isinstance(n, int) and n >= 0 for n in shape):
                raise ModelFileError(f"{self.path}: array {name!r} has no valid shape in {MANIFEST}")
            if math.prod(shape) * 8 > MODEL_FILE_LIMITS.max_member_bytes:
                raise ModelFileError(
                    f"{self.path}: array {name!r} declares shape {shape}: over {MODEL_FILE_LIMITS.max_member_bytes:,} bytes"
                )

    def member(self, name: str) -> bytes:
        """A member's bytes, checked against its SHA-256."""
        data = self._read(name, MODEL_FILE_LIMITS.max_member_bytes)
        if _sha256(data) != self.manifest["members"][name].get("sha256"):
            raise ModelFileError(f"{self.path}: member {name!r} fails its SHA-256 digest: the file is corrupt or was edited")
        return data

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays, as declared in ``model.json`` (shapes, dtypes) and finite."""
        declared = self.manifest["arrays"]
        if not declared:
            return {}
        if ARRAYS not in self.manifest["members"]:
            raise ModelFileError(f"{self.path}: {MANIFEST} declares arrays but the file has no {ARRAYS}")
        try:
            arrays = safetensors.numpy.load(self.member(ARRAYS))
        except (SafetensorError, KeyError, ValueError, TypeError) as error:  # KeyError: a dtype numpy lacks (BF16, F8_*)
            raise ModelFileError(
                f"{self.path}: {ARRAYS} is not readable by safetensors as numpy arrays: {type(error).__name__}: {error}"
            ) from None
        if sorted(arrays) != sorted(declared):
            raise ModelFileError(f"{self.path}: arrays {sorted(arrays)} do not match {MANIFEST}'s {sorted(declared)}")
        for name, array in arrays.items():
            spec = declared[name]
            if list(array.shape) != spec["shape"] or array.dtype.name != spec.get("dtype") or array.dtype.kind not in NUMERIC_KINDS:
                raise ModelFileError(
                    f"{self.path}: array {name!r} is {array.dtype.name} {list(array.shape)}; "
                    f"{MANIFEST} says {spec.get('dtype')} {spec['shape']}"
                )
            if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
                raise ModelFileError(f"{self.path}: array {name!r} holds non-finite values")
        return arrays

    def estimators(self, trusted: tuple[str, ...]) -> dict[str, Any]:
        """The scikit-learn estimators, each read as only the ``trusted`` types."""
        estimators = {}
        for member in sorted(self.manifest["members"]):
            if member.endswith(ESTIMATOR_SUFFIX):
                try:
                    estimators[member[: -len(ESTIMATOR_SUFFIX)]] = load_estimator(self.member(member), trusted)
                except EstimatorFileError as error:
                    raise ModelFileError(f"{self.path}: member {member!r}: {error}") from None
        return estimators


def require_array(arrays: Mapping[str, np.ndarray], name: str, shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
    """An array of a model file with an exact shape and dtype, else ``ValueError``."""
    if name not in arrays:
        raise ValueError(f"missing array {name!r}")
    array = arrays[name]
    if array.shape != tuple(shape) or array.dtype != np.dtype(dtype):
        raise ValueError(f"array {name!r} is {array.dtype} {array.shape}; expected {np.dtype(dtype)} {tuple(shape)}")
    return array


def require_names(items: Mapping[str, Any], names: set[str] | frozenset[str], what: str = "arrays") -> None:
    """Raise ``ValueError`` unless the file holds exactly the arrays (or estimators) ``names``."""
    missing, extra = sorted(set(names) - set(items)), sorted(set(items) - set(names))
    if missing or extra:
        raise ValueError(f"{what} do not fit the parameters: missing {missing}, unexpected {extra}")


_LOAD_ERRORS = (ValueError, KeyError, TypeError, AttributeError, OverflowError)


class SavableModel:
    """Mixin: ``save``/``load`` through model files.

    Subclasses set ``KIND`` and, if they hold scikit-learn estimators, ``TRUSTED_TYPES``; they
    implement ``layout`` (their inputs, features and outputs, with units), ``_export`` (the fitted
    model as :class:`ModelParts`), ``_from_params`` (an unfitted model from the file's parameters, which
    checks them against fixed bounds: it runs before any array or estimator is read) and
    ``_load_parts`` (checks the arrays and estimators and sets the fitted state). Both raise
    ``ValueError`` (or ``KeyError``, ``TypeError``) on what does not fit; ``load`` turns those
    into ``ModelFileError`` naming the file.
    """

    KIND: ClassVar[str] = ""
    TRUSTED_TYPES: ClassVar[tuple[str, ...]] = ()

    def layout(self) -> dict[str, Any]:
        """What the model maps: its input, feature and output columns, each named with its unit."""
        raise NotImplementedError

    def _export(self) -> ModelParts:
        raise NotImplementedError

    @classmethod
    def _from_params(cls: type[_Model], params: Mapping[str, Any]) -> _Model:
        raise NotImplementedError

    def _load_parts(self, parts: ModelParts) -> None:
        raise NotImplementedError

    def save(self, path: PathLike) -> None:
        """Save the fitted model to ``path`` (a zip of JSON, safetensors and skops members; no pickle)."""
        write_model_file(path, self.KIND, self.layout(), self._export())

    @classmethod
    def load(cls: type[_Model], path: PathLike) -> _Model:
        """Load a model saved by ``save``; raises ``ModelFileError`` on any bad, tampered or retired file."""
        with _ModelArchive(path, cls.KIND) as archive:
            params = archive.manifest["params"]
            try:
                model = cls._from_params(params)
            except _LOAD_ERRORS as error:
                raise ModelFileError(f"{path}: invalid {cls.KIND} parameters: {error}") from None
            if archive.manifest["layout"] != json.loads(json.dumps(model.layout())):
                raise ModelFileError(f"{path}: its feature layout {archive.manifest['layout']!r} is not this model's {model.layout()!r}")
            parts = ModelParts(params, archive.arrays(), archive.estimators(cls.TRUSTED_TYPES))
        try:
            model._load_parts(parts)
        except _LOAD_ERRORS as error:
            if isinstance(error, ModelFileError):
                raise
            raise ModelFileError(f"{path}: invalid {cls.KIND} model: {error}") from None
        return model
