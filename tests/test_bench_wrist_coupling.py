"""benchmarks/identify_wrist_coupling.py: its coupled instrument is the identified one plus the coupling, and nothing more."""

import numpy as np
from benchmark_scripts import load_script

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity import instrument_model as model
from dvrk_gym.fidelity.identify import start_camera_pose
from dvrk_gym.sim.robot import body

coupling = load_script("identify_wrist_coupling")


def _rows(n: int = 60) -> tuple[np.ndarray, np.ndarray]:
    X, y = load_paper_phase1()
    return model.real_commands(X[:n], y[:n]), model.initial_vector(start_camera_pose())


def test_without_coupling_the_pixels_are_the_identifications():
    commands, theta = _rows()
    np.testing.assert_array_equal(coupling.coupled_pixels(theta, 0.0, commands), model.predict_pixels(theta, commands))


def test_the_coupling_turns_the_wrist_yaw_by_c_times_the_wrist_pitch():
    commands, theta = _rows()
    q_true = model.true_joints(theta, commands)
    q_true[:, 5] += 0.3 * q_true[:, 4]
    expected = model.pixels_of_camera_points(model.camera_points(theta, model.tape_positions(theta, q_true)))
    moved = coupling.coupled_pixels(theta, 0.3, commands)
    np.testing.assert_array_equal(moved, expected)
    assert np.max(np.abs(moved - model.predict_pixels(theta, commands))) > 1.0  # it moves the tape by pixels


def test_the_tape_is_moved_inside_only():
    original = body.MARKER
    with coupling.tape_at(0.0085):
        assert body.MARKER.offset_m[1] == 0.0085
        assert body.MARKER.offset_m[::2] == original.offset_m[::2] and body.MARKER.half_extents_m == original.half_extents_m
    assert body.MARKER is original
