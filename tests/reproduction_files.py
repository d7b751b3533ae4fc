"""Comparing two ``dvrk-gym reproduce`` run folders file for file."""

from pathlib import Path

SAME_BYTES = ("calibration/*.npz", "calibration/*.zip", "calibration/calibration_table.json", "debridement/*.json")
"""The files of a run folder that two runs with the same settings write byte for byte: the
calibrators' models and Phase I/II data, the calibration table and every debridement cell."""


def files_that_differ(first: Path, second: Path) -> list[str]:
    """The files of :data:`SAME_BYTES` whose bytes differ between two run folders, relative to
    them, after checking that both runs wrote the same ones (and at least one)."""
    names = sorted(str(path.relative_to(first)) for pattern in SAME_BYTES for path in first.glob(pattern))
    assert names, f"{first} holds none of {SAME_BYTES}"
    assert names == sorted(str(path.relative_to(second)) for pattern in SAME_BYTES for path in second.glob(pattern))
    return [name for name in names if (first / name).read_bytes() != (second / name).read_bytes()]
