"""A run folder: results cached on disk for one set of settings, so an interrupted run resumes.

A folder opened with settings is stamped with them (a JSON file in the folder); opening it
again with other settings is refused with an error that names what differs, so results
made with one set of settings are never mixed with another's. Each result is a file in the
folder: :meth:`RunFolder.cached` loads it when it is there, else makes and saves it.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

logger = logging.getLogger(__name__)

T = TypeVar("T")


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    """A JSON tree as ``{"a.b": leaf}`` (lists are leaves)."""
    if not isinstance(value, dict):
        return {prefix: value}
    flat: dict[str, Any] = {}
    for key, item in value.items():
        flat.update(_flatten(item, f"{prefix}.{key}" if prefix else str(key)))
    return flat


def settings_differences(found: Any, wanted: Any) -> list[str]:
    """What differs between two JSON settings trees: ``["seed: 0 there, 1 here", ...]``."""
    there, here = _flatten(found), _flatten(wanted)
    missing = object()
    return [
        f"{key}: {there.get(key, 'unset')!r} there, {here.get(key, 'unset')!r} here"
        for key in sorted(set(there) | set(here))
        if there.get(key, missing) != here.get(key, missing)
    ]


def read_settings(folder: str | os.PathLike, stamp: str) -> dict[str, Any] | None:
    """The settings a folder was stamped with, or None when it has no stamp."""
    path = Path(folder) / stamp
    return json.loads(path.read_text()) if path.exists() else None


class RunFolder:
    """A folder of cached results made with one set of settings.

    Args:
        path: the folder (created if missing).
        settings: what the results depend on, JSON-able; None opens the folder without a
            stamp (any caller may use its files).
        stamp: the name of the file holding the settings.

    Raises:
        ValueError: the folder is stamped with other settings (the message lists them).
    """

    def __init__(self, path: str | os.PathLike, settings: Mapping[str, Any] | None = None, stamp: str = "settings.json") -> None:
        self.path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)
        self.stamp = self.path / stamp
        self.made_s: dict[str, float] = {}
        """Wall time of each result made (not loaded) by :meth:`cached`, by stage, seconds."""
        if settings is not None:
            self._check_and_stamp(settings)

    def _check_and_stamp(self, settings: Mapping[str, Any]) -> None:
        wanted = json.loads(json.dumps(settings))  # tuples become lists, as they come back from the stamp
        found = read_settings(self.path, self.stamp.name)
        if found is not None and found != wanted:
            differences = "; ".join(settings_differences(found, wanted))
            raise ValueError(
                f"{self.path} holds a run with other settings ({differences}; see {self.stamp}); use another --out or delete it"
            )
        self.stamp.write_text(json.dumps(wanted, indent=1, sort_keys=True))

    def file(self, name: str) -> Path:
        """The path of a result in the folder."""
        return self.path / name

    def has(self, name: str) -> bool:
        """Whether the folder holds the result ``name``."""
        return self.file(name).exists()

    def cached(
        self, name: str, make: Callable[[], T], load: Callable[[Path], T], save: Callable[[T, Path], Any], stage: str | None = None
    ) -> T:
        """The result ``name``: loaded from the folder if there, else made, saved and timed.

        Args:
            name: the result's file name in the folder.
            make: computes the result.
            load: reads the result from its path.
            save: writes the result to its path.
            stage: the key of its time in :attr:`made_s` (default: the file name's stem).
        """
        path = self.file(name)
        if path.exists():
            logger.info("%s: loading %s", stage or path.stem, path)
            return load(path)
        start = time.perf_counter()
        value = make()
        self.made_s[stage or path.stem] = time.perf_counter() - start
        save(value, path)
        return value

    def read_json(self, name: str) -> Any:
        """A JSON result of the folder."""
        return json.loads(self.file(name).read_text())

    def write_json(self, name: str, value: Any) -> Path:
        """Write a JSON result into the folder (indented); returns its path."""
        path = self.file(name)
        path.write_text(json.dumps(value, indent=1))
        return path
