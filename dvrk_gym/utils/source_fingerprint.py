"""A fingerprint of the installed dvrk_gym: which simulator made a run folder's results.

Cached results are only valid for the code that made them. Between versions the simulator
changes (the identified instrument in ``sim/identified.py``, the Phase I collector, the
detector, the calibrators...), and a run folder resumed by another version would mix its
new results with the old ones. So every stamped :class:`~dvrk_gym.utils.run_folder.RunFolder`
records :func:`source_fingerprint`, and a folder with another one is refused.

What it covers: the files a wheel of the package installs (``pyproject.toml``'s packages and
package data), so that an editable checkout and a wheel built from it agree: every Python
module (``*.py``), ``py.typed``, and every file under ``data/`` (the authors' data files,
their READMEs and licences); each by its path relative to the package directory and its
bytes, hashed in the order of the sorted paths with SHA-256; and the version installed
(:func:`importlib.metadata.version`; None where the package has no metadata, e.g. run from a
bare checkout). Only the digest decides whether two fingerprints are the same: an editable
install keeps its version number while its code changes, and the same code installed under
another number makes the same results.

What it skips: every other file of a checkout (a folder's README, an editor's backup
``foo.py~`` or swap file, a merge's ``*.orig``), which a wheel would not install and the
code does not read; ``__pycache__`` folders (bytecode, and numba's on-disk caches of
``sim/compiled/kernels.py``), numba cache files (``*.nbi``, ``*.nbc``) wherever they lie,
and hidden files and folders (names starting with ``.``).

What it does not cover: the versions of the dependencies (numpy, torch, PyBullet, numba),
Python's and the machine's, which may move a result's last bits too.

The package directory holds about 1.2 MB; it is hashed once per process (:func:`functools.cache`).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DISTRIBUTION = "dvrk-gym"
"""The distribution whose version the fingerprint records (``pyproject.toml``'s project name)."""
PACKAGE_ROOT = Path(__file__).resolve().parent.parent
"""The ``dvrk_gym`` package directory whose files are hashed."""
SKIPPED_FOLDERS = frozenset({"__pycache__"})
"""Folders never hashed, wherever they lie (bytecode and numba's caches)."""
SKIPPED_SUFFIXES = (".pyc", ".pyo", ".nbi", ".nbc")
"""File endings never hashed: bytecode and numba's cache index and data files."""
MODULE_SUFFIX = ".py"
"""Python modules, hashed wherever they lie in the package."""
TYPED_MARKER = "py.typed"
"""The package's typing marker, package data at its root."""
DATA_FOLDER = "data"
"""The package-data folder: every file under it is hashed."""
SHORT_DIGEST_CHARS = 12
"""Hex digits of the digest shown in messages (48 bits)."""


@dataclass(frozen=True)
class SourceFingerprint:
    """Which dvrk_gym made something.

    Attributes:
        version: the installed distribution's version, or None when it has no metadata.
        sha256: hex SHA-256 of the package directory's files (see the module docstring).
    """

    version: str | None
    sha256: str

    def to_json(self) -> dict[str, str | None]:
        """As stored in a run folder's stamp: ``{"version": ..., "sha256": ...}``."""
        return {"version": self.version, "sha256": self.sha256}

    @classmethod
    def from_json(cls, value: Any) -> SourceFingerprint | None:
        """A fingerprint read from a stamp; None when ``value`` is not one (missing or edited)."""
        if not isinstance(value, dict) or set(value) != {"version", "sha256"}:
            return None
        version, sha256 = value["version"], value["sha256"]
        if not (version is None or isinstance(version, str)) or not isinstance(sha256, str):
            return None
        return cls(version=version, sha256=sha256)

    def short(self) -> str:
        """For messages: ``dvrk_gym 0.1.0, source sha256 1a2b3c4d5e6f``."""
        return f"dvrk_gym {self.version or '(version unknown)'}, source sha256 {self.sha256[:SHORT_DIGEST_CHARS]}"


def _hashed(name: str) -> bool:
    return not name.startswith(".") and not name.endswith(SKIPPED_SUFFIXES)


def _installed(relative: str) -> bool:
    """Whether a wheel installs the file at ``relative`` (``/``-separated, from the package directory)."""
    return relative.endswith(MODULE_SUFFIX) or relative == TYPED_MARKER or relative.startswith(DATA_FOLDER + "/")


def package_files(root: str | os.PathLike) -> list[str]:
    """The files a fingerprint of ``root`` covers: paths relative to it, ``/``-separated, sorted."""
    root = Path(root)
    found: list[str] = []
    for folder, folders, files in os.walk(root):
        folders[:] = [name for name in folders if name not in SKIPPED_FOLDERS and _hashed(name)]  # not walked into
        relative = Path(folder).relative_to(root)
        found.extend(path for path in ((relative / name).as_posix() for name in files if _hashed(name)) if _installed(path))
    return sorted(found)


def tree_sha256(root: str | os.PathLike) -> str:
    """Hex SHA-256 over the files of ``root`` (:func:`package_files`): each one's relative path,
    its size in bytes and its bytes, one after another in path order (the path and size framing
    keep a renamed file or bytes moved from one file to the next from hashing the same)."""
    root = Path(root)
    digest = hashlib.sha256()
    for name in package_files(root):
        data = (root / name).read_bytes()
        digest.update(name.encode("utf-8") + b"\0" + len(data).to_bytes(8, "little"))
        digest.update(data)
    return digest.hexdigest()


def package_version() -> str | None:
    """The installed dvrk-gym's version, or None when it has no metadata (not installed)."""
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return None


@functools.cache
def source_fingerprint() -> SourceFingerprint:
    """The fingerprint of the dvrk_gym this process runs, computed once per process."""
    return SourceFingerprint(version=package_version(), sha256=tree_sha256(PACKAGE_ROOT))
