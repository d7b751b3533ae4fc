"""Checks of settings by type and range, each error naming the setting and what is allowed.

No silent coercion: ``"8"`` is not an int, ``True`` is not a number, ``2.0`` is not a
count, ``nan`` and complex numbers are refused. numpy's scalar types count as the Python
types they stand for (``np.int64(3)`` is an int, ``np.float32(0.1)`` a float).
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dvrk_gym import paper


def _shown(value: Any) -> str:
    return f"{value!r} ({type(value).__name__})"


def check_int(name: str, value: Any, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int, if it is an integer (not a bool) in ``[low, high]``.

    Raises:
        ValueError: the message names ``name`` and the allowed range.
    """
    allowed = f"an int in [{'-inf' if low is None else low}, {'inf' if high is None else high}]"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be {allowed}, got {_shown(value)}")
    number = int(value)
    if (low is not None and number < low) or (high is not None and number > high):
        raise ValueError(f"{name} must be {allowed}, got {number}")
    return number


def check_float(
    name: str, value: Any, *, low: float | None = None, high: float | None = None, low_open: bool = False, unit: str = ""
) -> float:
    """``value`` as a float, if it is a finite real number (not a bool) in ``[low, high]``
    (``(low, high]`` with ``low_open``).

    Args:
        unit: shown after the range in the error ("m", "s"...).

    Raises:
        ValueError: the message names ``name`` and the allowed range.
    """
    bracket = "(" if low_open else "["
    allowed = f"a finite number in {bracket}{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
    allowed += f" {unit}" if unit else ""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be {allowed}, got {_shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an int beyond any float (10**400)
        raise ValueError(f"{name} must be {allowed}, got a number too large for a float") from None
    too_low = low is not None and (number <= low if low_open else number < low)
    if not math.isfinite(number) or too_low or (high is not None and number > high):
        raise ValueError(f"{name} must be {allowed}, got {number}")
    return number


def check_bool(name: str, value: Any) -> bool:
    """``value`` if it is a bool (numpy's too), else ValueError naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {_shown(value)}")
    return bool(value)


def check_choice(name: str, value: Any, choices: Sequence[Any]) -> Any:
    """``value`` if it is one of ``choices`` (compared by type and value), else ValueError listing them."""
    if not any(type(value) is type(choice) and value == choice for choice in choices):
        raise ValueError(f"{name} must be one of {list(choices)}, got {_shown(value)}")
    return value


FILE_STEM = r"[A-Za-z0-9_+\-][A-Za-z0-9_+.\-]*"
"""What :func:`check_file_stem` takes: letters, digits and ``_ + - .``, not first a ``.``."""


def check_file_stem(name: str, value: Any) -> str:
    """``value`` if it can name a file or folder by itself: no folders, no hidden or partial files.

    Raises:
        ValueError: anything else (``"../x"``, ``"a b/c"``, ``".hidden"``, ``""``), naming ``name``.
    """
    if not isinstance(value, str) or not re.fullmatch(FILE_STEM, value):
        raise ValueError(f"{name} {value!r} must be letters, digits and _ + - . (not starting with '.'), no folders")
    return value


def check_resolution(name: str, value: Any, low: tuple[int, int] = (16, 16), high: tuple[int, int] = (7680, 4320)) -> tuple[int, int]:
    """An image size ``(width, height)`` in pixels: two ints within ``low`` and ``high``."""
    allowed = f"(width, height): two ints from {low[0]}x{low[1]} to {high[0]}x{high[1]} pixels"
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise ValueError(f"{name} must be {allowed}, got {_shown(value)}")
    try:
        width = check_int(f"{name}[0] (width)", value[0], low[0], high[0])
        height = check_int(f"{name}[1] (height)", value[1], low[1], high[1])
    except ValueError as error:
        raise ValueError(f"{error}; {name} must be {allowed}") from None
    return width, height


def check_endoscope_resolution(name: str, value: Any) -> tuple[int, int]:
    """An endoscope image size ``(width, height)`` in pixels: two ints in :func:`check_resolution`'s
    range, in the authors' 1920 x 1080 aspect (16:9, to a pixel; the detector's noise, search
    boxes and whole pixels scale with the width alone). Configs that stamp a run folder check
    it before making the folder.

    Raises:
        ValueError: naming ``name``, and for another aspect a size that keeps it.
    """
    width, height = check_resolution(name, value)
    paper_width, paper_height = paper.ENDOSCOPE_RESOLUTION_PX
    matching = width * paper_height / paper_width  # the height of the paper's aspect
    if abs(matching - height) > 1.0:
        example = f"{width} x {round(matching)}" if matching >= 16 else "320 x 180"
        raise ValueError(
            f"{name} must keep the endoscope's {paper_width} x {paper_height} aspect (16:9, to a pixel), "
            f"got {width} x {height}; e.g. {example}"
        )
    return width, height


Bounds = tuple[float | None, float | None, bool]
"""A float field's (low, high, low_open) for :func:`check_float_fields`."""


def check_float_fields(owner: str, config: Any, bounds: Mapping[str, Bounds], units: Mapping[str, str] | None = None) -> None:
    """Check each named float field of a frozen dataclass against its bounds and store it as a float.

    Args:
        owner: the class's name, shown in errors (``"GripperConfig.jaw_friction must be ..."``).
        config: the dataclass instance (its ``__post_init__`` calls this).
        bounds: ``{field: (low, high, low_open)}``; None for an open end.
        units: ``{field: unit}`` shown after the range.
    """
    for name, (low, high, low_open) in bounds.items():
        value = check_float(
            f"{owner}.{name}", getattr(config, name), low=low, high=high, low_open=low_open, unit=(units or {}).get(name, "")
        )
        object.__setattr__(config, name, value)


def check_int_fields(owner: str, config: Any, bounds: Mapping[str, tuple[int | None, int | None]]) -> None:
    """Check each named int field of a frozen dataclass against ``{field: (low, high)}`` and store it as an int."""
    for name, (low, high) in bounds.items():
        object.__setattr__(config, name, check_int(f"{owner}.{name}", getattr(config, name), low, high))
