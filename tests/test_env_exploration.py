"""CalibrationExploration-v0 and the Phase I tools."""

import numpy as np
import pytest

from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, Phase1Data, clean_mask, collect_phase1
from dvrk_gym.envs import exploration as ex


def test_episode_starts_at_a_workspace_corner(make_env):
    env = make_env("dvrk_gym/CalibrationExploration-v0", bias="none")
    corners = ex.workspace_corners()
    for corner in range(4):
        _, info = env.reset(seed=0, options={"corner": corner})
        np.testing.assert_allclose(info["reported_position"], corners[corner], atol=1e-9)
    with pytest.raises(ValueError, match="corner"):
        env.reset(options={"corner": 7})


def test_spaces_are_the_documented_ones(make_env):
    env = make_env("dvrk_gym/CalibrationExploration-v0")
    assert env.action_space.shape == (6,)
    assert set(env.observation_space.spaces) == {"reported_pose", "jaw_angle", "marker_seen", "marker_pixels", "marker_camera_position"}
    np.testing.assert_allclose(np.degrees(env.action_space.low[3:]), [-90, -15, -180], atol=1e-4)
    np.testing.assert_allclose(np.degrees(env.action_space.high[3:]), [90, 25, -150], atol=1e-4)


def test_episode_is_truncated_after_max_steps(make_env):
    env = make_env("dvrk_gym/CalibrationExploration-v0", max_steps=3)
    env.reset(seed=0)
    flags = [env.step(env.action_space.sample())[3] for _ in range(3)]
    assert flags == [False, False, True]


def test_reported_pose_is_the_command_and_truth_differs_under_paper_bias(make_env):
    env = make_env("dvrk_gym/CalibrationExploration-v0", bias="paper")
    env.reset(seed=0)
    action = np.array([0.04, 0.04, -0.150, 0.3, 0.1, -2.9], dtype=np.float32)
    obs, _, _, _, info = env.step(action)
    np.testing.assert_allclose(obs["reported_pose"][:3], action[:3], atol=1e-6)
    nominal_tip_offset = np.linalg.norm(info["true_tip_position"] - info["reported_position"])
    assert 0.008 < nominal_tip_offset < 0.013  # the tip is about a jaw length from the reported point


def test_paper_policy_moves_about_a_millimetre_per_pause_with_three_rotations():
    policy = PaperExplorationPolicy(seed=0)
    start = {"reported_pose": np.array([0.01, 0.02, -0.15, 0, 0, 0], dtype=np.float32)}
    policy.reset(start)
    actions = np.array([policy(start) for _ in range(30)])
    positions = actions[:, :3]
    assert np.all(positions[0::3] == positions[1::3]) and np.all(positions[1::3] == positions[2::3])
    steps = np.linalg.norm(np.diff(positions[::3], axis=0), axis=1)
    assert np.all(steps <= 0.001 + 1e-6) and np.median(steps) == pytest.approx(0.001, abs=1e-6)
    yaw, pitch, roll = np.degrees(actions[:, 3:]).T
    assert yaw.min() >= -90 and yaw.max() <= 90 and pitch.min() >= -15 and pitch.max() <= 25
    assert roll.min() >= -180 and roll.max() <= -150
    assert len(np.unique(yaw)) == len(yaw)


def test_cleaning_rule_keeps_only_agreeing_stereo_pairs():
    left = np.array([[100.0, 50.0], [100.0, 50.0], [np.nan, np.nan], [100.0, 50.0]])
    right = np.array([[90.0, 50.5], [90.0, 58.0], [90.0, 50.0], [90.0, 50.0]])
    position = np.array([[0.0, 0.0, 0.18], [0.0, 0.0, 0.18], [np.nan] * 3, [0.0, 0.0, 5.0]])
    areas = np.array([[900.0, 880.0], [900.0, 900.0], [0.0, 900.0], [900.0, 900.0]])
    np.testing.assert_array_equal(clean_mask(left, right, position, areas, image_width=1920), [True, False, False, False])
    slivers = np.tile(left[:1], (4, 1)), np.tile(right[:1], (4, 1)), np.tile(position[:1], (4, 1))
    areas = np.array([[1000.0, 1000.0], [990.0, 1010.0], [1000.0, 150.0], [120.0, 130.0]])
    np.testing.assert_array_equal(clean_mask(*slivers, areas, image_width=1920), [True, True, False, False])


@pytest.mark.slow
def test_collect_phase1_loses_samples_to_the_wrist_like_the_paper(make_env, tmp_path):
    env = make_env("dvrk_gym/CalibrationExploration-v0", bias="paper", max_steps=30)
    data = collect_phase1(env, PaperExplorationPolicy(seed=0), n_trajectories=12, progress=False)
    assert data.n_raw == 360
    kept = data.n_kept / data.n_raw
    assert 0.20 < kept < 0.60  # the paper kept 37% (57 trajectories here: 36%); the wrist hides it otherwise
    clean = data.cleaned()
    assert np.isfinite(clean.X).all() and clean.X.shape == (data.n_kept, 6)
    assert clean.y.shape == (data.n_kept, 3)
    data.save(tmp_path / "phase1.npz")
    loaded = Phase1Data.load(tmp_path / "phase1.npz")
    np.testing.assert_array_equal(loaded.kept, data.kept)
    np.testing.assert_array_equal(loaded.camera_position, data.camera_position)
