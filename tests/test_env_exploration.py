"""CalibrationExploration-v0 and the Phase I tools."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, Phase1Data, clean_mask, collect_phase1, left_to_right_map
from dvrk_gym.envs import exploration as ex
from dvrk_gym.sim.robot.bias import BIAS_PRESETS


def test_episode_starts_at_a_workspace_corner(make_env):
    env = make_env("dvrk_gym/CalibrationExploration-v0", bias="none")
    corners = ex.workspace_corners()
    for corner in range(4):
        _, info = env.reset(seed=0, options={"corner": corner})
        np.testing.assert_allclose(info["reported_position"], corners[corner], atol=1e-9)
    with pytest.raises(ValueError, match="corner"):
        env.reset(options={"corner": 7})


def test_a_trajectory_starts_relaxed_unless_relax_false_keeps_the_cables_history(make_env):
    """Every trajectory started relaxed, and a harness giving the other envs' "relax" option was refused."""
    fresh = make_env("dvrk_gym/CalibrationExploration-v0")
    start = fresh.reset(seed=0, options={"corner": 0})[1]["true_tip_position"]
    env = make_env("dvrk_gym/CalibrationExploration-v0")
    env.action_space.seed(0)
    starts = {}
    for relax in (None, True, False):
        env.reset(seed=1, options={"corner": 1})
        for _ in range(20):
            env.step(env.action_space.sample())
        starts[relax] = env.reset(options={"corner": 0} if relax is None else {"corner": 0, "relax": relax})[1]["true_tip_position"]
    np.testing.assert_array_equal(starts[None], start)
    np.testing.assert_array_equal(starts[True], start)
    assert 1e-5 < np.linalg.norm(np.subtract(starts[False], start)) < 2e-3  # the hysteresis the trajectory left: 0.7 mm
    with pytest.raises(ValueError, match="option 'relax' must be True or False"):
        env.reset(options={"relax": 1})


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


@pytest.mark.parametrize("lag", [0.0, None], ids=["no settle lag", "paper's settle lag"])
def test_reported_pose_is_the_command_and_truth_differs_under_paper_bias(make_env, lag):
    bias = BIAS_PRESETS["paper"] if lag is None else dataclasses.replace(BIAS_PRESETS["paper"], wrist_settle_lag=lag)
    env = make_env("dvrk_gym/CalibrationExploration-v0", bias=bias)
    env.reset(seed=0)
    action = np.array([0.04, 0.04, -0.150, 0.3, 0.1, -2.9], dtype=np.float32)
    obs, _, _, _, info = env.step(action)
    miss = np.linalg.norm(obs["reported_pose"][:3] - action[:3])
    if lag == 0.0:
        assert miss <= 1e-6  # the encoders read the command
    else:
        # The wrist stopped a quarter of its step from the start pose short: the reported
        # tool frame, 9.1 mm of wrist offset from the pivot, is off by a fraction of that.
        assert 1e-5 < miss < 3e-3
    nominal_tip_offset = np.linalg.norm(info["true_tip_position"] - info["reported_position"])
    assert 0.008 < nominal_tip_offset < 0.013  # the tip is about a jaw length from the reported point
    unbiased = make_env("dvrk_gym/CalibrationExploration-v0", bias="none")
    unbiased.reset(seed=0)
    *_, unbiased_info = unbiased.step(action)
    cable_error = np.linalg.norm(info["true_tip_position"] - unbiased_info["true_tip_position"])
    assert cable_error > 3e-4  # the cables put the tip elsewhere than the same command without bias


def test_paper_policy_moves_2_mm_per_pause_with_its_own_and_three_random_rotations():
    policy = PaperExplorationPolicy(seed=0)
    start = {"reported_pose": np.array([*ex.workspace_corners()[0], 0, 0, 0], dtype=np.float32)}
    policy.reset(start)
    actions = np.array([policy(start) for _ in range(40)])
    positions = actions[:, :3]
    for k in range(1, 4):
        assert np.all(positions[0::4] == positions[k::4])
    steps = np.linalg.norm(np.diff(positions[::4], axis=0), axis=1)
    np.testing.assert_allclose(steps, 0.002, atol=1e-6)  # the authors' collector, and their rows
    # Straight from the corner (5 mm over the paper) towards a target 1 mm over it.
    heights = positions[::4, 2] - ex.PAPER_REPORTED_Z_M
    assert heights[0] == pytest.approx(0.005, abs=1e-6) and np.all(np.diff(heights) < 0) and heights[-1] > 0.001
    # The authors' code records the trajectory's orientation first at every pause.
    np.testing.assert_array_equal(actions[0::4, 3:], np.tile(actions[0, 3:], (10, 1)))
    yaw, pitch, roll = np.degrees(actions[:, 3:]).T
    assert yaw.min() >= -90 and yaw.max() <= 90 and pitch.min() >= -15 and pitch.max() <= 25
    assert roll.min() >= -180 and roll.max() <= -150
    random_yaws = np.delete(yaw, np.s_[0::4])
    assert len(np.unique(random_yaws)) == len(random_yaws)
    assert np.abs(np.diff(yaw)).max() <= 150.0 + 1e-4  # no extreme flips


def test_paper_policy_starts_the_next_trajectory_from_a_corner_after_its_target():
    """As the authors' collector did: the last pause lies within a step of the target, the next
    at a corner 5 mm over the paper, with the next trajectory's own orientation."""
    policy = PaperExplorationPolicy(seed=3)
    corners = ex.workspace_corners()
    start = {"reported_pose": np.array([*corners[2], 0, 0, 0], dtype=np.float32)}
    policy.reset(start)
    actions = np.array([policy(start) for _ in range(4 * 120)])
    pauses = actions[::4]
    jumps = np.flatnonzero(np.linalg.norm(np.diff(pauses[:, :3], axis=0), axis=1) > 0.002 + 1e-6)
    assert len(jumps) >= 2  # 120 pauses reach at least two targets
    for jump in jumps:
        after = pauses[jump + 1]
        assert np.min(np.linalg.norm(corners - after[:3], axis=1)) < 1e-6
        assert not np.allclose(after[3:], pauses[jump, 3:])  # a new trajectory, its own orientation
        assert pauses[jump, 2] - ex.PAPER_REPORTED_Z_M < 0.001 + 0.002  # the last pause near its target's height
    segments = np.split(pauses, jumps + 1)
    for segment in segments[1:-1]:
        np.testing.assert_array_equal(segment[:, 3:], np.tile(segment[0, 3:], (len(segment), 1)))


def test_cleaning_rule_keeps_pairs_within_12_px_of_the_grid_map():
    # Right = left shifted 70 px left (a plane at constant disparity), fitted from four points.
    grid_left = np.array([[800.0, 200.0], [1300.0, 200.0], [800.0, 700.0], [1300.0, 700.0]])
    grid_right = grid_left - [70.0, 0.0]
    to_right = left_to_right_map(grid_left, grid_right)
    left = np.array([[1000.0, 400.0], [1000.0, 400.0], [1000.0, 400.0], [np.nan, np.nan], [1000.0, 400.0]])
    right = np.array([[930.0, 400.0], [930.0, 411.0], [922.0, 391.0], [930.0, 400.0], [930.0, 412.5]])
    np.testing.assert_array_equal(clean_mask(left, right, to_right, image_width=1920), [True, True, False, False, False])
    # At 640 px wide the gate is 4 px.
    assert list(clean_mask(left / 3, right / 3, left_to_right_map(grid_left / 3, grid_right / 3), image_width=640)) == [
        True,
        True,
        False,
        False,
        False,
    ]


@pytest.mark.slow
def test_collect_phase1_loses_samples_to_the_wrist_like_the_paper(make_env, tmp_path):
    env = make_env("dvrk_gym/CalibrationExploration-v0", bias="paper", max_steps=30)
    data = collect_phase1(env, PaperExplorationPolicy(seed=0), n_trajectories=12, progress=False)
    assert data.n_raw == 360
    kept = data.n_kept / data.n_raw
    # The paper kept 37% (57 trajectories of 93 poses here: 37%); the wrist hides the tape, or it
    # falls outside the authors' search boxes, which these short paths near the corners meet more often.
    assert 0.10 < kept < 0.50
    clean = data.cleaned()
    assert np.isfinite(clean.X).all() and clean.X.shape == (data.n_kept, 6)
    assert clean.y.shape == (data.n_kept, 3)
    data.save(tmp_path / "phase1.npz")
    loaded = Phase1Data.load(tmp_path / "phase1.npz")
    np.testing.assert_array_equal(loaded.kept, data.kept)
    np.testing.assert_array_equal(loaded.camera_position, data.camera_position)


@pytest.mark.parametrize(
    ("n_trajectories", "seed", "message"),
    [(2.0, 0, "n_trajectories must be an int"), (True, 0, "n_trajectories must be an int"), (1, -1, "seed must be an int")],
)
def test_phase1_refuses_counts_and_seeds_that_are_not_ints_before_it_runs(n_trajectories, seed, message):
    env = gym.make("dvrk_gym/CalibrationExploration-v0", camera_resolution=(640, 360))
    try:
        with pytest.raises(ValueError, match=message):
            collect_phase1(env, PaperExplorationPolicy(seed=0), n_trajectories, seed=seed, progress=False)
    finally:
        env.close()
    grid = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=(640, 360))
    try:
        with pytest.raises(ValueError, match="Phase I runs on CalibrationExploration-v0, got GridTouchEnv"):
            collect_phase1(grid, PaperExplorationPolicy(seed=0), 1, progress=False)
    finally:
        grid.close()


def test_phase1_at_a_resolution_that_loses_the_grid_is_refused_before_it_collects():
    env = gym.make("dvrk_gym/CalibrationExploration-v0", camera_resolution=(64, 36))
    policy = PaperExplorationPolicy(seed=0)
    try:
        with pytest.raises(ValueError, match=r"camera_resolution of 64 x 36 px the endoscope does not see the printed grid"):
            collect_phase1(env, policy, n_trajectories=1, progress=False)
        assert env.unwrapped._steps == 0  # not one pose commanded
    finally:
        env.close()
