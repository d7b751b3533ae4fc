"""benchmarks/tour_order.py: the pushes split by the move before them, its flag, a run."""

import dataclasses
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from benchmark_scripts import ROOT, load_script, run_script, script_path

from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.calibration.pipeline import SETTINGS_STAMP
from dvrk_gym.envs.grid_touch import N_CIRCLES
from dvrk_gym.utils.run_folder import SOURCE_KEY

tour_order = load_script("tour_order")
SCRIPT = script_path("tour_order")


def test_the_pushes_are_split_by_whether_the_move_before_went_to_the_next_row():
    # one yaw (0): along a row towards -x twice, then back to +x on the next row, then along it once
    sent = np.array([[0.07, 0.02, 0], [0.06, 0.02, 0], [0.05, 0.02, 0], [0.07, 0.03, 0], [0.06, 0.03, 0]])
    pushes = np.array([[9.0, 9.0, 0], [1.0, 2.0, 0], [3.0, 4.0, 0], [-5.0, 6.0, 0], [5.0, 0.0, 0]])
    yaws = np.zeros(5)
    means = tour_order.pushes_by_move(sent, pushes, yaws)
    np.testing.assert_allclose(means[2], [[3.0, 2.0], [-5.0, 6.0]])  # the first touch has no move before it
    assert np.isnan(means[[0, 1, 3, 4]]).all()  # no pushes at the other yaws
    alone = tour_order.pushes_by_move(sent[:3], pushes[:3], yaws[:3])
    np.testing.assert_allclose(alone[2, 0], [2.0, 3.0])
    assert np.isnan(alone[2, 1]).all()  # no move to a next row
    with pytest.raises(ValueError, match="must be as long, got 5, 4, 5"):
        tour_order.pushes_by_move(sent, pushes[:4], yaws)


def test_it_refuses_a_folder_no_calibration_made(tmp_path):
    result = run_script(SCRIPT, "--calibration", str(tmp_path))
    assert result.returncode == 2 and "not a calibration run folder" in result.stderr.splitlines()[-1]


def test_it_refuses_a_calibration_another_dvrk_gym_made(small_calibration, tmp_path):
    """Its Phase I rows would be mixed with this version's simulation (every benchmark that reads
    a calibration does this through fidelity_table_runs.read_calibration)."""
    other = tmp_path / "other"
    shutil.copytree(small_calibration, other, ignore=shutil.ignore_patterns("*.lock"))
    stamp = json.loads((other / SETTINGS_STAMP).read_text())
    stamp[SOURCE_KEY] = {**stamp[SOURCE_KEY], "sha256": "ab" * 32}
    (other / SETTINGS_STAMP).write_text(json.dumps(stamp))
    result = run_script(SCRIPT, "--calibration", str(other))
    last = result.stderr.splitlines()[-1]
    assert (
        result.returncode == 2
        and "made by another version of dvrk_gym's simulator" in last
        and last.endswith("dvrk-gym calibrate --out NEW_FOLDER")
    )
    del stamp[SOURCE_KEY]
    (other / SETTINGS_STAMP).write_text(json.dumps(stamp))
    assert "has no source fingerprint" in run_script(SCRIPT, "--calibration", str(other)).stderr


def test_it_prints_both_orders_for_each_method_and_the_pushes_by_move(small_calibration):
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--calibration", str(small_calibration)], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    table = [line.split() for line in lines[2:8]]
    assert [(row[0], row[1]) for row in table] == [(m, o) for m in ("RBT", "DNN", "DNN+RF") for o in ("authors'", "row-major")]
    for row in table:
        cells = [float(v) for v in row[2:]]
        assert len(cells) == 7 and cells[-1] == pytest.approx(np.mean(cells[:-1]), abs=0.006)
    assert table[0][2:] != table[1][2:]  # the order changes the touches
    pushes = lines[lines.index(next(line for line in lines if line.startswith("2. Phase II pushes"))) + 1 :]
    assert [line.split()[0].rstrip(",") for line in pushes] == ["real", "real", "sim"]
    assert pushes[0].endswith("x after the next-row move minus along a row: -1.0")  # the authors' pushes, their first round
    assert pushes[1].endswith("x after the next-row move minus along a row: -0.4")  # and their second


def test_it_refuses_a_phase_ii_made_before_the_authors_tour(small_calibration, tmp_path):
    stale = tmp_path / "stale"
    shutil.copytree(small_calibration, stale)
    phase2 = Phase2Data.load(stale / "phase2.npz")
    assert phase2.in_authors_tour
    row_major = dataclasses.replace(phase2, circle=np.tile(np.arange(N_CIRCLES), len(phase2.circle) // N_CIRCLES))
    assert not row_major.in_authors_tour
    row_major.save(stale / "phase2.npz")
    result = run_script(SCRIPT, "--calibration", str(stale))
    assert result.returncode == 2 and "made before the authors' tour" in result.stderr.splitlines()[-1]
