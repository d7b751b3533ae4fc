"""Each env's success rule, its unit and its threshold, pinned from both sides.

A rule checked only where it says yes cannot tell a threshold of 1 mm from one of 1 m
(GridTouch's ``is_success`` once compared a distance in metres with the threshold times
1000 and called a 9.6 mm miss a success). Every rule here is checked on both sides of its
threshold, in the units its API states.
"""

import numpy as np
import pytest

from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.sim.endoscope.baseline import PAPER_BASELINE_M, TRUE_BASELINE_M
from dvrk_gym.sim.physics.scene import RECEPTACLE_CENTER_M, RECEPTACLE_INNER_SIZE_M, RECEPTACLE_WALL_HEIGHT_M
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.table import judge

GRID_TOUCH = "dvrk_gym/GridTouch-v0"


def _aimed_action(env, circle: int, offset_m=(0.0, 0.0)) -> np.ndarray:
    """The nominal command at a circle, moved by ``offset_m`` (x, y) metres in the paper's plane."""
    target = env.unwrapped.circle_centers[circle] + [offset_m[0], offset_m[1], 0.0]
    command = target - tool_pose(np.zeros(3), 0.0)[:3, 2] * kin.JAW_LENGTH_M
    return np.array([*command, 0.0], dtype=np.float32)


def _touch(env, offset_m):
    env.reset(seed=0, options={"circle": 17})
    observation, reward, _, _, info = env.step(_aimed_action(env, 17, offset_m))
    distance_m = float(np.linalg.norm(observation["achieved_goal"] - observation["desired_goal"]))
    return distance_m, reward, info


@pytest.mark.parametrize("offset_mm", [0.0, 0.6, 1.5, 9.6])
def test_grid_touch_success_is_a_distance_in_metres_within_the_threshold(make_env, offset_mm):
    env = make_env(GRID_TOUCH, bias="none", reward_type="sparse", distance_threshold_m=0.001)
    distance_m, reward, info = _touch(env, (offset_mm * 1e-3, 0.0))
    # The goals are in metres, as the endoscope triangulates them: its stereo calibration
    # (the authors' baseline, 1.3% short of the true one) puts every point the camera's
    # depth scale times as far away (the tape nearer still: its detector's right-image shift).
    # At the tests' 640 x 360 the circle's contour centroids sit up to about 0.04 px off its
    # projection, which moves its triangulated depth by up to about 0.6 mm.
    depth_scale = env.unwrapped.world.camera.depth_scale
    assert depth_scale == pytest.approx(PAPER_BASELINE_M / TRUE_BASELINE_M)
    assert distance_m == pytest.approx(offset_mm * 1e-3 * depth_scale, abs=0.6e-3)
    if offset_mm > 0.0:  # against the same circle's touch without offset, the circle's own error cancels
        achieved = []
        for offset in ((0.0, 0.0), (offset_mm * 1e-3, 0.0)):
            env.reset(seed=0, options={"circle": 17})
            achieved.append(env.step(_aimed_action(env, 17, offset))[0]["achieved_goal"].astype(np.float64))
        moved = float(np.linalg.norm(achieved[1] - achieved[0]))
        assert moved == pytest.approx(offset_mm * 1e-3 * depth_scale, abs=0.02e-3)
    assert info["is_success"] == (distance_m <= 0.001)
    assert reward == (0.0 if info["is_success"] else -1.0)  # the sparse reward agrees with is_success
    if offset_mm >= 1.5:
        assert not info["is_success"]  # a 1.5 mm or 9.6 mm miss is no success at 1 mm
    if offset_mm == 0.0:
        assert info["is_success"]


def test_grid_touch_threshold_is_the_configured_one(make_env):
    """The same 9.6 mm miss: a failure at 1 mm and 9 mm, a success at 10 mm and 20 mm."""
    for threshold_m, expected in ((0.001, False), (0.009, False), (0.010, True), (0.020, True)):
        env = make_env(GRID_TOUCH, bias="none", distance_threshold_m=threshold_m)
        distance_m, reward, info = _touch(env, (0.0096, 0.0))
        assert info["is_success"] is expected, (threshold_m, distance_m)
        assert reward == pytest.approx(-1e3 * distance_m)  # dense: minus the distance in millimetres
        assert info["mm_error"] == pytest.approx(9.6, abs=0.3)  # millimetres, as named


def test_grid_touch_reward_units_and_signs():
    from dvrk_gym.envs.grid_touch import GridTouchEnv

    env = GridTouchEnv(reward_type="sparse", distance_threshold_m=0.002, camera_resolution=(320, 180))
    try:
        desired = np.zeros(3)
        near, far = np.array([0.0019, 0, 0]), np.array([0.0021, 0, 0])
        assert env.compute_reward(near, desired, {}) == 0.0 and env.compute_reward(far, desired, {}) == -1.0
    finally:
        env.close()
    dense = GridTouchEnv(camera_resolution=(320, 180))
    try:
        assert dense.compute_reward(np.array([0.003, 0.004, 0.0]), np.zeros(3), {}) == pytest.approx(-5.0)  # -5 mm
        assert dense.compute_reward(np.zeros(3), np.zeros(3), {}) == 0.0
    finally:
        dense.close()


# ---------------------------------------------------------------- Debridement-v0's judge
@pytest.mark.parametrize(
    ("delivered", "pierced", "ratio", "above_top_m", "outcome"),
    [
        (True, True, 5.0, 0.01, judge.SUCCESS),  # in the receptacle: a success, however the grip went
        (False, True, 0.1, -0.001, judge.PIERCED),
        (False, False, judge.WELL_PLACED_RATIO, -0.001, judge.SLIPPED),  # the threshold itself is well placed
        (False, False, judge.WELL_PLACED_RATIO + 1e-9, -0.001, judge.MISSED),
        (False, False, 0.1, 1e-6, judge.MISSED),  # the tip closed above the fragment's top (metres)
        (False, False, 0.1, 0.0, judge.SLIPPED),
        (False, False, float("inf"), -0.001, judge.MISSED),
    ],
)
def test_debridement_outcome_rule(delivered, pierced, ratio, above_top_m, outcome):
    assert judge.judge(delivered, pierced, ratio, above_top_m) == outcome


def test_well_placed_threshold_and_offset_ratio_units():
    assert judge.WELL_PLACED_RATIO == 0.5
    size = np.array([0.0124, 0.0068, 0.0024])  # a pumpkin seed, metres
    assert judge.offset_ratio(np.array([0.0, 0.0]), size) == 0.0
    assert judge.offset_ratio(np.array([0.0062, 0.0]), size) == pytest.approx(1.0)  # on the outline along its length
    assert judge.offset_ratio(np.array([0.0, 0.0034]), size) == pytest.approx(1.0)  # and across it
    assert judge.offset_ratio(np.array([0.0031, 0.0]), size) == pytest.approx(0.5)


def test_receptacle_bounds_in_metres():
    center = RECEPTACLE_CENTER_M + [0.0, 0.0, 0.005]
    assert judge.in_receptacle(center)
    half = RECEPTACLE_INNER_SIZE_M / 2
    assert judge.in_receptacle(center + [half[0] - 1e-4, 0.0, 0.0])
    assert not judge.in_receptacle(center + [half[0] + 1e-4, 0.0, 0.0])
    assert not judge.in_receptacle(center + [0.0, half[1] + 1e-4, 0.0])
    assert not judge.in_receptacle(RECEPTACLE_CENTER_M + [0.0, 0.0, RECEPTACLE_WALL_HEIGHT_M + 1e-4])
    assert not judge.in_receptacle(RECEPTACLE_CENTER_M - [0.0, 0.0, 1e-4])
