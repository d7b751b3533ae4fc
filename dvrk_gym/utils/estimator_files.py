"""scikit-learn estimators as bytes, through ``skops.io``: written, and read back only as the types named.

:func:`dump_estimator` is ``skops.io.dumps`` (a zip of a JSON schema and ``.npy`` arrays,
deflated). :func:`load_estimator` reads such bytes without unpickling anything and without
trusting a size it has not checked:

1. the archive's declared sizes are bounded (:mod:`dvrk_gym.utils.bounded_zip`) before
   anything is inflated;
2. its ``schema.json`` is read within those limits, and every object it describes must be of
   a type of the caller's explicit ``trusted`` list and be built by one of skops' plain
   loaders (:data:`PLAIN_LOADERS`: no functions, methods or operators) -- stricter than
   skops, which also trusts its own defaults (any scikit-learn estimator, numpy's ufuncs...);
3. each ``.npy`` array's header must declare the bytes its member holds (numpy allocates what
   a header declares before reading), and no objects;
4. each decision tree's declared feature and output counts, which scikit-learn allocates
   from when it builds the tree, are bounded (:data:`MAX_TREE_FEATURES`, :data:`MAX_TREE_OUTPUTS`);
5. only then ``skops.io.loads(data, trusted=trusted)`` builds the object (numpy arrays with
   ``allow_pickle=False``).

What it returns is of a trusted type, but its values are the file's: the caller checks them
(a tree's child indices, say, which scikit-learn's prediction follows without bounds checks).
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import skops.io

from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, check_npy_members, open_archive, read_member

__all__ = ["ESTIMATOR_LIMITS", "EstimatorFileError", "dump_estimator", "load_estimator"]

ESTIMATOR_LIMITS = ArchiveLimits(max_file_bytes=256 * 2**20, max_members=50_000, max_member_bytes=128 * 2**20, max_total_bytes=256 * 2**20)
"""What one estimator's skops archive may hold: 256 MiB (a 100-tree forest on the paper's 1,939
rows takes about 22 MB inflated), 50,000 members (three arrays a tree)."""
SCHEMA = "schema.json"
"""The member of a skops archive that describes the object."""
SKOPS_PROTOCOLS = (2,)
"""The skops schema protocols read (skops 0.10 and later write protocol 2)."""
PLAIN_LOADERS = frozenset({"DictNode", "JsonNode", "ListNode", "NdArrayNode", "ObjectNode", "TreeNode", "TupleNode", "TypeNode"})
"""The skops loaders a file may use: containers, JSON values, numpy arrays, objects of a
trusted type, scikit-learn's trees and the types of dict keys."""
MAX_TREE_FEATURES = 4096
MAX_TREE_OUTPUTS = 4096
"""The largest feature and output counts a decision tree may declare (scikit-learn allocates an
array of the output count before it reads the tree's nodes)."""


_SKOPS_ERRORS = (
    ValueError,
    TypeError,
    KeyError,
    AttributeError,
    IndexError,
    OverflowError,
    MemoryError,
    RecursionError,
    zipfile.BadZipFile,
)
"""What skops raises on a file it cannot build (its refusal of an untrusted type is a TypeError)."""


class EstimatorFileError(ValueError):
    """Bytes that are not a skops archive of the trusted types within the size limits."""


def dump_estimator(estimator: Any) -> bytes:
    """``estimator`` as skops bytes (deflated), the same bytes for equal estimators in any
    process on one platform and zlib (:func:`_canonical`)."""
    return _canonical(skops.io.dumps(estimator, compression=zipfile.ZIP_DEFLATED))


def _canonical(data: bytes) -> bytes:
    """A skops archive written again so that equal estimators give equal bytes.

    skops names each object by its ``id()`` (the schema's ``__id__`` fields and its arrays'
    ``<id>.npy`` members) and stamps each member with the time: two saves of one forest
    differ. Here the ids are numbered in the order :func:`_nodes` walks the schema (from 1:
    skops shares no object whose id is 0), the arrays numbered in the order it meets them, and every
    member dated 1980-01-01, as the model files around them are. Equal ids stay
    equal (skops reads them as shared references), so the same object is read back.
    """
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        schema = json.loads(archive.read(SCHEMA))
        numbers: dict[int, int] = {}
        files: dict[str, str] = {}
        for node in _nodes(schema):  # the same walk, so the same numbers, for the same schema
            if isinstance(node.get("__id__"), int):
                node["__id__"] = numbers.setdefault(node["__id__"], len(numbers) + 1)
            if isinstance(node.get("file"), str):
                node["file"] = files.setdefault(node["file"], f"{len(files)}.npy")
        members = {SCHEMA: json.dumps(schema, indent=2).encode("utf-8")}
        members.update({new: _zero_padding(archive.read(old)) for old, new in files.items()})
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, content in members.items():
            archive.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)), content, compress_type=zipfile.ZIP_DEFLATED)
    return out.getvalue()


def _zero_padding(npy: bytes) -> bytes:
    """An ``.npy`` member of a structured array (a tree's nodes) written again with the padding
    between its fields zeroed. numpy writes those bytes as they lie in memory, which for a
    tree skops has loaded is whatever the heap held: its saves differed each time and
    carried heap addresses. Other arrays are returned as they are."""
    array = np.load(io.BytesIO(npy), allow_pickle=False)
    if array.dtype.names is None:
        return npy
    clean = np.zeros(array.shape, dtype=array.dtype)
    for name in array.dtype.names:
        clean[name] = array[name]
    out = io.BytesIO()
    np.save(out, clean, allow_pickle=False)
    return out.getvalue()


def _nodes(schema: Any) -> Iterator[dict[str, Any]]:
    """Every object description in a skops schema (depth first, without recursion)."""
    stack = [schema]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            if "__class__" in item or "__loader__" in item:
                yield item
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)


def _json_int(node: Any, what: str, high: int) -> int:
    """The integer a skops ``JsonNode`` holds, within ``[1, high]``."""
    if not isinstance(node, dict) or node.get("__loader__") != "JsonNode" or not isinstance(node.get("content"), str):
        raise EstimatorFileError(f"a tree's {what} is not a JSON value")
    try:
        value = json.loads(node["content"])
    except ValueError:
        raise EstimatorFileError(f"a tree's {what} is not valid JSON") from None
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= high:
        raise EstimatorFileError(f"a tree declares {what} = {str(value)[:40]}; expected an int in [1, {high}]")
    return value


def _check_tree_sizes(node: dict[str, Any]) -> None:
    """A ``TreeNode``'s constructor arguments ``(n_features, n_classes, n_outputs)``, bounded."""
    reduce = node.get("__reduce__")
    args = reduce.get("args") if isinstance(reduce, dict) else None
    content = args.get("content") if isinstance(args, dict) else None
    if not isinstance(content, list) or len(content) != 3:
        raise EstimatorFileError("a tree's constructor arguments are not (n_features, n_classes, n_outputs)")
    _json_int(content[0], "n_features", MAX_TREE_FEATURES)
    _json_int(content[2], "n_outputs", MAX_TREE_OUTPUTS)


def _check_schema(schema: Any, trusted: frozenset[str]) -> None:
    """Refuse a schema with a type outside ``trusted``, a loader outside :data:`PLAIN_LOADERS` or an oversized tree."""
    if not isinstance(schema, dict) or schema.get("protocol") not in SKOPS_PROTOCOLS:
        protocol = schema.get("protocol") if isinstance(schema, dict) else None
        raise EstimatorFileError(f"skops protocol {protocol!r}; expected one of {list(SKOPS_PROTOCOLS)}")
    for node in _nodes(schema):
        kind = f"{node.get('__module__')}.{node.get('__class__')}"
        if kind not in trusted:
            raise EstimatorFileError(f"holds a {kind[:200]}; the trusted types are {sorted(trusted)}")
        loader = node.get("__loader__")
        if loader not in PLAIN_LOADERS:
            raise EstimatorFileError(f"uses the skops loader {str(loader)[:100]!r}; only {sorted(PLAIN_LOADERS)} are allowed")
        if loader == "TreeNode":
            _check_tree_sizes(node)


def load_estimator(data: bytes, trusted: Sequence[str], limits: ArchiveLimits = ESTIMATOR_LIMITS) -> Any:
    """The object in skops bytes, if it holds only ``trusted`` types within ``limits``.

    Args:
        data: bytes written by :func:`dump_estimator` (or ``skops.io.dumps``).
        trusted: every type the object may contain, by full name
            (``"sklearn.ensemble._forest.RandomForestRegressor"``, ``"builtins.dict"``...).
        limits: the archive's size limits.

    Raises:
        EstimatorFileError: not a skops archive, larger than the limits, a type or loader
            not allowed, a tree of more features or outputs than the bounds, or anything
            skops refuses while building the object.
    """
    allowed = frozenset(trusted)
    try:
        with open_archive(data, limits) as archive:
            schema = json.loads(read_member(archive, SCHEMA, limits))
            check_npy_members(archive)
    except KeyError:
        raise EstimatorFileError(f"not a skops archive: no {SCHEMA}") from None
    except (ArchiveLimitError, ValueError, RecursionError) as error:
        raise EstimatorFileError(f"unreadable skops archive: {error}") from None
    _check_schema(schema, allowed)
    try:
        return skops.io.loads(data, trusted=sorted(allowed))
    except _SKOPS_ERRORS as error:
        raise EstimatorFileError(f"skops refused it ({type(error).__name__}: {str(error)[:300]})") from None
