"""The assembled world: perception on pixels against geometry, independence, clean-up."""

import numpy as np
import pytest

from dvrk_gym.envs.exploration import sample_paper_poses
from dvrk_gym.sim.physics.scene import grid_circle_centers
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

MIN_FACE_AREA_PX = 100
"""About an eighth of the tape's area seen face-on at 1920 x 1080 (about 840 px)."""


@pytest.fixture(scope="module")
def full_hd_world():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(1920, 1080)))
    yield world
    world.close()


def _paper_poses(n: int, seed: int = 0):
    return sample_paper_poses(np.random.default_rng(seed), n)


@pytest.mark.slow
def test_pixel_detection_agrees_with_geometric_visibility(full_hd_world):
    """Seen whole: the detected centre is within 1 px of the projected centre.
    Hidden from every sample ray: not detected.

    "Seen whole" also asks for at least MIN_FACE_AREA_PX of tape: seen edge-on, the
    0.1 mm tape is a sliver a pixel wide whose centroid cannot beat the pixel grid (the
    Phase I cleaning rule drops those too)."""
    world = full_hd_world
    whole = hidden = 0
    for pose in _paper_poses(120):
        world.move_to(pose)
        detection = world.observe_marker()
        expected_left, expected_right = world.camera.project(world.true_marker_position())
        sides = (
            ("left", detection.left_uv, expected_left[0], detection.left_area_px),
            ("right", detection.right_uv, expected_right[0], detection.right_area_px),
        )
        for side, uv, expected, area in sides:
            fraction = world.marker_visible_fraction(side)
            if fraction == 1.0 and area >= MIN_FACE_AREA_PX:
                whole += 1
                assert np.isfinite(uv).all(), f"{side} camera missed a fully visible marker"
                assert np.linalg.norm(uv - expected) < 1.0
            elif fraction == 0.0:
                hidden += 1
                assert not np.isfinite(uv).all(), f"{side} camera saw a marker the wrist hides"
    assert whole >= 10 and hidden >= 10  # the sample must exercise both checks


def test_all_35_circles_are_detected_near_their_projections(full_hd_world):
    grid = full_hd_world.observe_grid()
    assert len(grid) == 35 and all(d.seen_both for d in grid)
    left, right = full_hd_world.camera.project(grid_circle_centers())
    detected_left = np.array([d.left_uv for d in grid])
    assert np.abs(detected_left - left).max() < 0.5
    positions = full_hd_world.camera.to_world(np.array([d.camera_position for d in grid]))
    assert np.abs(positions - grid_circle_centers()).max() < 0.5e-3  # triangulated to half a mm


def test_triangulate_of_project_is_identity(full_hd_world):
    camera = full_hd_world.camera
    points = grid_circle_centers() + [0.0, 0.0, 0.01]
    np.testing.assert_allclose(camera.to_world(camera.triangulate(*camera.project(points))), points, atol=1e-12)


def test_reported_pose_is_nominal_kinematics_and_truth_differs_under_bias():
    world = DvrkWorld(WorldConfig(bias="paper", camera_resolution=(320, 180)))
    try:
        pose = kin.pose_from_euler([0.04, 0.04, -0.15], 0.2, 0.1, -2.9)
        world.move_to(pose)
        np.testing.assert_allclose(world.reported_pose(), pose, atol=1e-9)
        assert np.linalg.norm(world.true_pose()[:3, 3] - pose[:3, 3]) > 1e-4
        np.testing.assert_allclose(world.robot.wrist_yaw_frame(), kin.link_frames(world.q_true, world.cable.true_dh)[5], atol=1e-6)
    finally:
        world.close()


def test_moves_advance_the_simulated_clock_at_the_speed_limit():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(320, 180)))
    try:
        start = kin.pose_from_euler([0.01, 0.04, -0.15], 0.0, 0.05, -2.95)
        world.move_to(start)
        before = world.clock.time_s
        result = world.move_to(_shifted(start, [0.06, 0.0, 0.0]))
        assert world.clock.time_s - before == pytest.approx(result.duration_s)
        # 6 cm at up to 6 cm/s with 0.2 s ramps, plus settling
        assert result.duration_s == pytest.approx(1.0 + 0.2 + world.config.motion.settle_time_s, rel=1e-6)
    finally:
        world.close()


def _shifted(pose, offset):
    moved = pose.copy()
    moved[:3, 3] += offset
    return moved


def test_unreachable_pose_raises_or_is_clamped_on_request():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(320, 180)))
    try:
        far = kin.pose_from_euler([0.04, 0.04, -0.15], 0.0, 0.0, -1.0)
        with pytest.raises(ik.UnreachablePoseError):
            world.move_to(far)
        result = world.move_to(far, clamp_to_limits=True)
        assert result.joints_clamped.any()
    finally:
        world.close()


def test_close_frees_the_server_and_is_idempotent():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(320, 180)))
    world.close()
    world.close()
    assert not world.physics.is_open


def test_bad_world_config_is_a_clear_error():
    with pytest.raises(ValueError, match="camera_resolution"):
        WorldConfig(camera_resolution=(0, 10))
    with pytest.raises(ValueError, match="pixel_noise_px"):
        WorldConfig(pixel_noise_px=-1.0)
