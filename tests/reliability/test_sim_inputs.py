"""The simulator's own building blocks given nonsense (from a review's probes of the physics
and perception code): each refused with a ValueError naming what is wrong, before anything
moves, never a silent NaN, a coercion or an error from deep inside."""

import numpy as np
import pytest

from dvrk_gym.sim.endoscope.camera import PAPER_INTRINSICS, StereoCamera, default_camera_pose
from dvrk_gym.sim.endoscope.noise import PixelNoise, whole_pixels
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.world import DvrkWorld, WorldConfig


@pytest.mark.parametrize("time_step_s", [float("nan"), -1.0, 0.0, 5.0, True, "0.01"])
def test_a_physics_time_step_that_is_not_a_short_positive_time_is_refused(time_step_s):
    with pytest.raises(ValueError, match="time_step_s must be a finite number in \\(0, 0.1\\] s"):
        Physics(time_step_s=time_step_s)


@pytest.mark.parametrize("width", [float("nan"), 0, -640, 640.0, True])
def test_an_image_width_that_is_not_a_positive_int_is_refused(width):
    with pytest.raises(ValueError, match="width_px must be an int in \\[1, inf\\]"):
        PixelNoise(1.0, width)
    with pytest.raises(ValueError, match="width_px must be an int"):
        whole_pixels(np.zeros(2), width)


@pytest.mark.parametrize(
    ("keywords", "name"),
    [
        ({"baseline_m": True}, "baseline_m"),
        ({"near_m": "0.1"}, "near_m"),
        ({"far_m": 0.005}, "far_m"),
        ({"calibrated_baseline_m": -1.0}, "calibrated_baseline_m"),
    ],
)
def test_stereo_camera_numbers_of_the_wrong_kind_or_order_are_refused(keywords, name):
    with pytest.raises(ValueError, match=f"^{name} must be a finite number"):
        StereoCamera(PAPER_INTRINSICS, **keywords)


def test_a_yaw_that_is_not_finite_is_refused_not_taken_for_the_first_paper_yaw():
    for function in (kin.nearest_paper_yaw, kin.paper_pitch_roll):
        with pytest.raises(ValueError, match="yaw_rad must be finite"):
            function(float("nan"))
        with pytest.raises(ValueError, match="yaw_rad must be finite"):
            function(np.array([0.0, np.inf]))
    with pytest.raises(ValueError, match="yaw, pitch, roll must be finite"):
        kin.pose_from_euler(np.array([0.04, 0.04, -0.15]), float("nan"), 0.0, 0.0)
    assert kin.nearest_paper_yaw(0.1) == 0.0


def test_world_config_refuses_a_detector_of_another_kind_and_keeps_its_own_camera_pose():
    with pytest.raises(ValueError, match="marker_noise must be a DetectionNoise"):
        WorldConfig(marker_noise={"core_px": 1.0})
    pose = default_camera_pose()
    config = WorldConfig(camera_pose=pose)
    pose[0, 3] = 9.0  # the caller's array changes after the check
    assert config.camera_pose[0, 3] == default_camera_pose()[0, 3]
    assert not config.camera_pose.flags.writeable
    # compared and hashed by value, as a frozen config should be (it raised: an array's == is elementwise)
    same, moved = WorldConfig(camera_pose=default_camera_pose()), WorldConfig(camera_pose=pose)
    assert config == same and hash(config) == hash(same) and len({config, same, moved, WorldConfig()}) == 3
    assert config != moved and config != WorldConfig() and WorldConfig() == WorldConfig()


def test_a_refused_move_leaves_the_world_as_it_was():
    world = DvrkWorld(WorldConfig(camera_resolution=(640, 360)))
    try:
        before = (world.q_cmd.copy(), world.q_true.copy(), world.reported_pose().copy())
        with pytest.raises(ValueError, match="q must be 6 finite joint values"):
            world.move_joints_floats([0.0, 0.0, float("nan"), 0.0, 0.0, 0.0])
        pose = world.reported_pose()
        with pytest.raises(ValueError, match="limits must be a MotionLimits"):
            world.move_to(pose, limits="fast")
        np.testing.assert_array_equal(world.q_cmd, before[0])
        np.testing.assert_array_equal(world.q_true, before[1])
        np.testing.assert_array_equal(world.reported_pose(), before[2])
        world.move_to(pose)  # and it still moves
    finally:
        world.close()


def test_a_render_that_fails_while_the_arm_is_retracted_puts_the_arm_back():
    world = DvrkWorld(WorldConfig(camera_resolution=(640, 360)))
    try:
        tool = world.robot.wrist_yaw_frame().copy()
        render = world.render

        def left_only(side="left"):
            if side == "right":
                raise RuntimeError("the renderer died")
            return render(side)

        world.render = left_only
        with pytest.raises(RuntimeError, match="the renderer died"):
            world._render_retracted()
        np.testing.assert_array_equal(world.robot.wrist_yaw_frame(), tool)
    finally:
        world.close()
