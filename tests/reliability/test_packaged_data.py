"""The authors' packaged real data is read within bounds and refused if it was changed."""

from __future__ import annotations

import io
import shutil
import types
from pathlib import Path

import numpy as np
import numpy.lib.format as npy_format
import pytest

from dvrk_gym import paper
from dvrk_gym.calibration import datasets
from dvrk_gym.calibration.datasets import MAX_PACKAGED_BYTES, load_paper_phase1, load_paper_table_runs

PACKAGE_ROOT = Path(datasets.__file__).resolve().parents[1]


@pytest.fixture
def package_copy(tmp_path, monkeypatch):
    """A copy of the package's data folder that the loaders read instead of the installed one."""
    shutil.copytree(PACKAGE_ROOT / "data", tmp_path / "data")
    monkeypatch.setattr(datasets, "resources", types.SimpleNamespace(files=lambda package: tmp_path))
    return tmp_path


def test_the_copy_as_released_loads(package_copy):
    X, y = load_paper_phase1()
    assert X.shape == (paper.REAL_PHASE1_ROWS, 6) and y.shape == (paper.REAL_PHASE1_ROWS, 3)
    assert load_paper_table_runs().method.shape == (paper.REAL_TABLE_TOUCHES,)


@pytest.mark.parametrize(
    ("folder", "name", "load"),
    [
        (paper.REAL_PHASE1_PACKAGE_DIR, "X_train.npy", load_paper_phase1),
        (paper.REAL_PHASE1_PACKAGE_DIR, "y_train.npy", load_paper_phase1),
        (paper.REAL_TABLE_PACKAGE_DIR, "table_runs.npz", load_paper_table_runs),
    ],
)
def test_a_changed_value_is_refused(package_copy, folder, name, load):
    path = package_copy.joinpath(*folder, name)
    data = bytearray(path.read_bytes())
    data[-3] ^= 0x01  # the last bytes of a value (or of the zip's directory): it still parses
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=f"{name} is not the one released.*reinstall"):
        load()


def test_a_file_larger_than_the_bound_is_refused_before_it_is_read_whole(package_copy):
    path = package_copy.joinpath(*paper.REAL_PHASE1_PACKAGE_DIR, "X_train.npy")
    path.write_bytes(path.read_bytes() + b"\0" * MAX_PACKAGED_BYTES)
    with pytest.raises(ValueError, match="X_train.npy is larger than 1,048,576 bytes"):
        load_paper_phase1()


def _npy(header: dict, body: bytes) -> bytes:
    stream = io.BytesIO()
    npy_format.write_array_header_1_0(stream, header)
    return stream.getvalue() + body


@pytest.mark.parametrize(
    ("x_bytes", "message"),
    [
        (_npy({"descr": "<f8", "fortran_order": False, "shape": (10**11, 6)}, b"\0" * 64), "declares .* but holds 64 bytes"),
        (_npy({"descr": "<c16", "fortran_order": False, "shape": (1939, 6)}, b"\0" * 16 * 1939 * 6), "dtype complex128"),
        (_npy({"descr": "<U8", "fortran_order": False, "shape": (1939, 6)}, b"\0" * 32 * 1939 * 6), "dtype <U8"),
        (_npy({"descr": "<f8", "fortran_order": False, "shape": (1939, 6)}, np.full(1939 * 6, np.nan).tobytes()), "not finite"),
    ],
)
def test_what_the_parser_meets_past_the_checksum_is_a_clear_error(monkeypatch, x_bytes, message):
    real = datasets._read_packaged
    monkeypatch.setattr(datasets, "_read_packaged", lambda folder, name: x_bytes if name == "X_train.npy" else real(folder, name))
    with pytest.raises(ValueError, match=message):
        load_paper_phase1()
