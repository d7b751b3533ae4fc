"""Data sets as frozen dataclasses of arrays, saved as plain ``.npz`` (never pickles)."""

from __future__ import annotations

from dataclasses import fields
from os import PathLike
from typing import TypeVar

import numpy as np

from dvrk_gym.calibration.models.serialization import ModelFileError, read_arrays
from dvrk_gym.utils.atomic import atomic_open

_Record = TypeVar("_Record", bound="ArrayRecord")


class ArrayRecord:
    """Mixin for a frozen dataclass whose fields are all numpy arrays of equal length."""

    def save(self, path: str | PathLike) -> None:
        """Write every field to an ``.npz`` file at exactly ``path`` (no suffix added), atomically."""
        with atomic_open(path) as stream:
            np.savez(stream, **{f.name: getattr(self, f.name) for f in fields(self)})

    @classmethod
    def load(cls: type[_Record], path: str | PathLike) -> _Record:
        """Read a file written by :meth:`save`; refuse files of another kind or with pickles."""
        names = {f.name for f in fields(cls)}
        try:
            data = read_arrays(path)  # sizes bounded, headers checked against the bytes, never a pickle
        except ModelFileError as error:
            raise ValueError(f"{path} is not a readable {cls.__name__} file: {error}") from None
        if set(data) != names:
            raise ValueError(f"{path} is not {cls.__name__} data: arrays {sorted(data)}, expected {sorted(names)}")
        return cls(**{name: data[name] for name in names})
