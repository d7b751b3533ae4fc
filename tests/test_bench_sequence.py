"""benchmarks/fidelity_sequence.py: the step between the protocol's pauses, real and simulated."""

import numpy as np
import pytest
from benchmark_scripts import load_script

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy
from dvrk_gym.envs import exploration

sequence = load_script("fidelity_sequence")


def test_pause_steps_pair_each_row_with_the_next_one_at_its_orientation():
    angles = np.deg2rad([[0, 0, -170], [40, 10, -160], [-30, 5, -155], [0.5, 0.5, -170.5], [60, -10, -150]])
    positions = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.003, 0.004, 0], [0.003, 0.004, 0]], dtype=float)
    steps = sequence.pause_steps(angles, positions)
    np.testing.assert_allclose(steps, [[3, 0.005]])  # rows 0 and 3 only; 5 mm in x and y
    assert sequence.pause_steps(angles, positions, tolerance_deg=0.1).shape == (0, 2)
    with pytest.raises(ValueError, match="expected"):
        sequence.pause_steps(angles[:, :2], positions)


def test_the_real_rows_pause_every_2_mm_as_the_authors_collector_and_the_simulated_policy_do():
    X, y = load_paper_phase1()
    steps = sequence.pause_steps(X[:, 3:], y)
    assert len(steps) == 341
    assert abs(np.median(steps[steps[:, 0] >= 2, 1]) - 0.002) < 1e-4  # not the paper's text's 1 mm
    policy = PaperExplorationPolicy(seed=0)
    start = {"reported_pose": np.array([*exploration.workspace_corners()[1], 0, 0, 0])}
    policy.reset(start)
    actions = np.array([policy(start) for _ in range(4 * 20)])
    simulated = sequence.pause_steps(actions[:, 3:], actions[:, :3])
    # In x and y: the path also descends 4 mm from the corner to the target, so a little under 2 mm.
    assert 0.95 * paper.PHASE1_STEP_M < np.median(simulated[:, 1]) <= paper.PHASE1_STEP_M + 1e-9
