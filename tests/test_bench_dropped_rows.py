"""benchmarks/fidelity_dropped_rows.py: its maps keep what the map says, and it prints both parts."""

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
from benchmark_scripts import ROOT, load_script, script_path

from dvrk_gym.sim.robot import body
from dvrk_gym.sim.robot import kinematics as kin

SCRIPT = script_path("fidelity_dropped_rows")
dropped = load_script("fidelity_dropped_rows")


def test_a_map_over_the_variable_the_drops_follow_gives_them_back():
    rng = np.random.default_rng(0)
    sim = rng.uniform(0.0, 1.0, size=(20_000, 2))
    # A "real" robot commanded the same rows twice as often and kept them by x alone: 0.8
    # below 0.5, 0.2 above. Its kept rows are a sample of that.
    keep = np.where(sim[:, 0] < 0.5, 0.8, 0.2)
    commanded = np.repeat(sim, 2, axis=0)
    real = commanded[rng.uniform(size=len(commanded)) < np.repeat(keep, 2)]
    edges = [np.linspace(0.0, 1.0, 11), np.linspace(0.0, 1.0, 3)]
    weights, unmatched = dropped.map_weights(sim, real, edges, raw_scale=2.0)
    assert unmatched == 0
    assert np.isclose(weights.sum() * 2.0, len(real))  # every real row is spread over its cell's raw rows
    np.testing.assert_allclose(weights[sim[:, 0] < 0.5].mean(), 0.8, atol=0.02)
    np.testing.assert_allclose(weights[sim[:, 0] >= 0.5].mean(), 0.2, atol=0.02)
    # A map over y alone cannot tell the two halves apart: every row gets the mean, 0.5.
    weights_y, _ = dropped.map_weights(sim, real, [np.linspace(0.0, 1.0, 2), np.linspace(0.0, 1.0, 11)], raw_scale=2.0)
    np.testing.assert_allclose(weights_y, 0.5, atol=0.03)


def test_real_rows_where_no_simulated_row_lies_are_counted_off_the_map():
    sim = np.array([[0.1], [0.2]])
    real = np.array([[0.15], [0.9], [0.95], [5.0]])  # 5.0 lies past the last edge: the last cell
    weights, unmatched = dropped.map_weights(sim, real, [np.array([0.0, 0.5, 1.0])], raw_scale=1.0)
    assert unmatched == 3
    np.testing.assert_array_equal(weights, [0.5, 0.5])


def test_weighted_shares_and_medians():
    yaw_index = np.array([0, 0, 0, 2, 2, 4])
    pitch = np.array([5.0, 1.0, 3.0, -2.0, 7.0, 9.0])
    shares, medians = dropped.weighted_shares_and_medians(yaw_index, pitch, np.ones(6))
    np.testing.assert_allclose(shares, [3 / 6, 0, 2 / 6, 0, 1 / 6])
    assert medians[0] == 3.0 and medians[4] == 9.0 and np.isnan(medians[1])
    # Weight moves the median: 7 degrees carries three times the weight of -2.
    _, medians = dropped.weighted_shares_and_medians(yaw_index, pitch, np.array([1.0, 1.0, 1.0, 1.0, 3.0, 1.0]))
    assert medians[2] == 7.0


def test_it_prints_both_parts():
    result = subprocess.run([sys.executable, str(SCRIPT), "--trajectories", "3"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("yaw "))
    assert [line.split()[0] for line in lines[header + 1 : header + 6]] == ["-90", "-45", "+0", "+45", "+90"]
    second = next(i for i, line in enumerate(lines) if line.startswith("2. Share per nearest yaw"))
    real = lines[second + 1].split()
    assert real[-11:] == ["0.13", "0.30", "0.28", "0.20", "0.09", "|", "11.7", "7.6", "-1.0", "-3.0", "-1.1"]  # the authors' rows
    maps = [line for line in lines[second + 3 :] if "(real rows off the map:" in line]
    assert len(maps) == 9 and maps[0].startswith("the reported yaw, pitch, roll")


def test_row_variables_read_the_line_of_sight_and_the_tape_frame():
    q = np.array([0.1, -0.2, 0.13, -2.8, 0.3, -0.4])
    frame = body.marker_frame(q, kin.PSM_DH)
    tape = body.marker_position(q, kin.PSM_DH)
    x_axis, y_axis, z_axis = frame[:3, 0], frame[:3, 1], frame[:3, 2]

    def variables(camera_position: np.ndarray) -> np.ndarray:
        camera = np.eye(4)
        camera[:3, 3] = camera_position
        world = SimpleNamespace(camera=SimpleNamespace(pose=camera), cable=SimpleNamespace(true_dh=kin.PSM_DH))
        return dropped.row_variables(q[None, :], world)[0]  # type: ignore[arg-type]

    behind = variables(tape - 0.1 * y_axis)  # looking along the jaws from behind them
    assert abs(behind[0]) < 1e-6
    beside = variables(tape + 0.1 * x_axis)  # from the tape frame's +x side: 90 deg off the jaws, azimuth 0
    np.testing.assert_allclose(beside[:2], [90.0, 0.0], atol=1e-6)
    above = variables(tape + 0.1 * z_axis)  # from its +z side: azimuth 90
    np.testing.assert_allclose(above[:2], [90.0, 90.0], atol=1e-6)
    # With the camera's axes the base's, the jaws' direction and the face normal are the frame's y and z.
    np.testing.assert_allclose(above[2:4], y_axis[:2], atol=1e-12)
    np.testing.assert_allclose(above[4:6], z_axis[:2], atol=1e-12)
    np.testing.assert_allclose(above[6:9], np.rad2deg(q[3:6]), atol=1e-12)
