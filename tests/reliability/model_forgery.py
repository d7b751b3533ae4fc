"""A careful forger's tools: edit a model file's JSON, arrays or skops members and rewrite every
size and SHA-256 so that the file is consistent, as anyone could (the digest is no signature)."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import safetensors.numpy

MANIFEST = "model.json"
ARRAYS = "arrays.safetensors"


def read_members(path: Path) -> dict[str, bytes]:
    """Every member of a zip, by name, in order."""
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def write_members(path: Path, members: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> Path:
    """A zip of these members, in this order."""
    with zipfile.ZipFile(path, "w", compression=compression) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


def resign(members: dict[str, bytes]) -> dict[str, bytes]:
    """The members with the manifest's sizes and digests made to fit the others."""
    manifest = json.loads(members[MANIFEST])
    manifest["members"] = {
        name: {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()} for name, data in members.items() if name != MANIFEST
    }
    return {**members, MANIFEST: json.dumps(manifest).encode()}


def edit_manifest(path: Path, edit: Callable[[dict], None], sign: bool = True) -> Path:
    """Edit ``model.json`` (``edit`` changes it in place); with ``sign``, sizes and digests rewritten to fit."""
    members = read_members(path)
    manifest = json.loads(members[MANIFEST])
    edit(manifest)
    members[MANIFEST] = json.dumps(manifest).encode()
    return write_members(path, resign(members) if sign else members)


def edit_params(path: Path, **params) -> Path:
    """The file with other parameters (for a two-phase file, the nested ones given as dicts)."""
    return edit_manifest(path, lambda manifest: manifest["params"].update(params))


def edit_arrays(path: Path, edit: Callable[[dict[str, np.ndarray]], None], declare: bool = True) -> Path:
    """Edit the safetensors arrays; with ``declare``, the manifest's shapes and dtypes follow them."""
    members = read_members(path)
    arrays = dict(safetensors.numpy.load(members[ARRAYS]))
    edit(arrays)
    members[ARRAYS] = safetensors.numpy.save({name: np.ascontiguousarray(value) for name, value in arrays.items()})
    if declare:
        manifest = json.loads(members[MANIFEST])
        manifest["arrays"] = {name: {"shape": list(value.shape), "dtype": value.dtype.name} for name, value in arrays.items()}
        members[MANIFEST] = json.dumps(manifest).encode()
    return write_members(path, resign(members))


def edit_skops(path: Path, member: str, edit: Callable[[dict, dict[str, bytes]], None]) -> Path:
    """Edit one skops member's schema and files (``edit(schema, files)`` changes them in place), re-signed."""
    members = read_members(path)
    files = read_members(io.BytesIO(members[member]))
    schema = json.loads(files.pop("schema.json"))
    edit(schema, files)
    inner = io.BytesIO()
    write_members(inner, {**files, "schema.json": json.dumps(schema).encode()})
    members[member] = inner.getvalue()
    return write_members(path, resign(members))


def tree_nodes(schema: dict) -> list[dict]:
    """The schema's tree descriptions (skops ``TreeNode``), in order of the forest's trees."""
    found, stack = [], [schema]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            if item.get("__loader__") == "TreeNode":
                found.append(item)
            stack.extend(reversed(list(item.values())))
        elif isinstance(item, list):
            stack.extend(reversed(item))
    return found


def edit_tree(path: Path, member: str, edit: Callable[[np.ndarray], None], tree: int = 0) -> Path:
    """Edit the node array (scikit-learn's structured ``NODE_DTYPE``) of one tree of a forest member."""

    def change(schema: dict, files: dict[str, bytes]) -> None:
        name = tree_nodes(schema)[tree]["content"]["content"]["nodes"]["file"]
        nodes = np.load(io.BytesIO(files[name]), allow_pickle=False)
        edit(nodes)
        stream = io.BytesIO()
        np.save(stream, nodes, allow_pickle=False)
        files[name] = stream.getvalue()

    return edit_skops(path, member, change)
