"""The assembled world: perception on pixels against geometry, independence, clean-up."""

import numpy as np
import pytest

from dvrk_gym import paper
from dvrk_gym.envs.exploration import sample_paper_poses
from dvrk_gym.sim.endoscope.baseline import true_baseline_m
from dvrk_gym.sim.endoscope.noise import DetectionNoise, whole_pixels
from dvrk_gym.sim.physics.scene import grid_circle_centers
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.body import marker_corners
from dvrk_gym.sim.world import DvrkWorld, WorldConfig


@pytest.fixture(scope="module")
def full_hd_world():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(1920, 1080)))
    yield world
    world.close()


def _paper_poses(n: int, seed: int = 0):
    return sample_paper_poses(np.random.default_rng(seed), n)


@pytest.mark.slow
def test_pixel_detection_agrees_with_geometric_visibility(full_hd_world):
    """Mostly seen (over half the sample rays reach the tape's faces that face the camera):
    detected, inside the tape's projected bounding box. Hidden from every sample ray: not
    detected. (The tape is folded over a jaw's edge, so which of its sides the camera sees
    moves the centroid within that box.)"""
    world = full_hd_world
    seen = hidden = 0
    for pose in _paper_poses(120):
        world.move_to(pose)
        detection = world.observe_marker()
        corners_left, corners_right = world.camera.project(marker_corners(world.q_true, world.cable.true_dh))
        for side, uv, corners in (("left", detection.left_uv, corners_left), ("right", detection.right_uv, corners_right)):
            fraction = world.marker_visible_fraction(side)
            if fraction > 0.5:
                seen += 1
                assert np.isfinite(uv).all(), f"{side} camera missed a mostly visible marker"
                assert np.all(uv >= corners.min(axis=0) - 0.5) and np.all(uv <= corners.max(axis=0) + 0.5)
            elif fraction == 0.0:
                hidden += 1
                assert not np.isfinite(uv).all(), f"{side} camera saw a marker the wrist hides"
    assert seen >= 10 and hidden >= 10  # the sample must exercise both checks


def test_all_35_circles_are_detected_near_their_projections(full_hd_world):
    grid = full_hd_world.observe_grid()
    assert len(grid) == 35 and all(d.seen_both for d in grid)
    left, right = full_hd_world.camera.project(grid_circle_centers())
    detected_left = np.array([d.left_uv for d in grid])
    assert np.abs(detected_left - left).max() < 0.5
    # The authors' triangulation scales positions by the camera's depth scale (its short baseline).
    camera = full_hd_world.camera
    positions = camera.to_world(np.array([d.camera_position for d in grid]) / camera.depth_scale)
    assert np.abs(positions - grid_circle_centers()).max() < 0.5e-3  # triangulated to half a mm


def test_triangulate_of_project_is_identity(full_hd_world):
    camera = full_hd_world.camera
    points = grid_circle_centers() + [0.0, 0.0, 0.01]
    triangulated = camera.triangulate(*camera.project(points))
    np.testing.assert_allclose(camera.to_world(triangulated / camera.depth_scale), points, atol=1e-12)


def test_reported_pose_is_nominal_kinematics_and_truth_differs_under_bias():
    world = DvrkWorld(WorldConfig(bias="paper", camera_resolution=(320, 180)))
    try:
        pose = kin.pose_from_euler([0.04, 0.04, -0.15], 0.2, 0.1, -2.9)
        world.move_to(pose)
        # The encoders read the measured joints: the command's, but for the wrist's settle lag.
        measured = world.cable.measured_joints(world.q_cmd)
        np.testing.assert_allclose(world.reported_pose(), kin.forward_kinematics(measured), atol=1e-12)
        assert np.abs(measured - world.q_cmd)[4:].max() > 0.0 and np.array_equal(measured[:4], world.q_cmd[:4])
        np.testing.assert_allclose(kin.forward_kinematics(world.q_cmd), pose, atol=1e-9)
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


def test_noisy_detections_are_whole_pixels_and_their_depth_follows_the_disparity(full_hd_world):
    world = full_hd_world
    rng = np.random.default_rng(0)
    seen = 0
    for pose in _paper_poses(40, seed=3):
        world.move_to(pose)
        detection = world.observe_marker(noise_rng=rng)
        if not detection.seen_both:
            continue
        seen += 1
        for uv in (detection.left_uv, detection.right_uv):
            np.testing.assert_array_equal(uv, np.floor(uv))
        disparity = np.linalg.norm(detection.left_uv - detection.right_uv)
        depth = world.camera.intrinsics.fx * world.camera.calibrated_baseline_m / disparity
        assert detection.camera_position[2] == pytest.approx(depth)
    assert seen >= 5


def test_a_float_path_move_sets_the_body_when_the_body_or_physics_is_next_asked_for():
    world = DvrkWorld(WorldConfig(bias="paper", camera_resolution=(320, 180)))
    rng = np.random.default_rng(3)
    try:
        wrist = world.robot.wrist_yaw_frame()
        for i in range(6):
            q = ik.inverse_kinematics(kin.pose_from_euler(np.array([0.03, 0.04, -0.14 - 0.005 * i]), 0.2 * i, 0.1, -3.0))
            world.move_joints_floats(q.tolist(), noise_rng=rng)
            assert world._body_behind  # not set yet: a GridTouch step sets it once, if at all
            moved = world.robot.wrist_yaw_frame()  # asking for the body sets it first
            assert not world._body_behind
            np.testing.assert_allclose(moved[:3, 3], kin.last_frame(world.q_true, world.cable.true_dh)[:3, 3], atol=1e-6)
            assert not np.allclose(moved, wrist)
            wrist = moved
        world.move_joints_floats(q.tolist(), noise_rng=rng)
        image = world.render("left")  # through the physics: the body is set before the render
        world.robot.set_joints(world.q_true, world.jaw_angle)  # set now, the eager way
        assert np.array_equal(image, world.render("left"))
        saved = world.physics.client.saveState()
        world.reset_robot(q, floats=True)
        assert world._body_behind
        world.restore_physics(saved)  # an env's reset: the saved joints, then its own
        assert world._body_behind  # still pending: q_true did not change
        frame = world.robot.wrist_yaw_frame()
        np.testing.assert_allclose(frame[:3, 3], kin.last_frame(world.q_true, world.cable.true_dh)[:3, 3], atol=1e-6)
        world.rebuild()  # a rebuilt body starts where rebuild puts it, with nothing pending
        assert not world._body_behind
    finally:
        world.close()


def test_the_marker_seen_without_the_printed_circles_is_the_marker_seen_with_them(full_hd_world, monkeypatch):
    """Above the circles' plane nothing can lie behind them, so leaving them out of the render
    (cheaper) gives the same detections; below it, they stay in."""
    from dvrk_gym.sim import world as world_module
    from dvrk_gym.sim.physics import scene

    world = full_hd_world
    hidden_renders = []
    real_hidden = scene.printed_circles_hidden

    def counting(physics, grid):
        hidden_renders.append(grid)
        return real_hidden(physics, grid)

    monkeypatch.setattr(world_module, "printed_circles_hidden", counting)
    low = ik.inverse_kinematics(kin.pose_from_euler(np.array([0.04, 0.042, scene.PRINT_TOP_Z_M - 0.004]), 0.0, 0.0, -3.0))
    for i, pose in enumerate(_paper_poses(40, seed=5)):
        if i == 20:
            world.move_joints(low)  # the tape at or below the paper: the circles stay in
            before = len(hidden_renders)
            world.observe_marker()
            assert len(hidden_renders) == before
            continue
        world.move_to(pose)
        before = len(hidden_renders)
        got = world.observe_marker()
        assert len(hidden_renders) == before + 1  # the paper's poses hold the tape well above the paper
        with monkeypatch.context() as m:
            m.setattr(world_module, "MARKER_CIRCLE_CLEARANCE_M", np.inf)  # never hidden
            expected = world.observe_marker()
        assert np.array_equal(got.left_uv, expected.left_uv, equal_nan=True)
        assert np.array_equal(got.right_uv, expected.right_uv, equal_nan=True)
    # The circles are printed again afterwards, and hiding them does take them out of a render.
    window = world.camera.window_around(world.camera.project(grid_circle_centers()[:1])[0][0], 12)
    shown = world.camera.render(world.physics.client, "left", window)
    with real_hidden(world.physics, world.scene.grid):
        hidden = world.camera.render(world.physics.client, "left", window)
    assert shown.min() < 40 <= hidden.min()  # a black disc, then white paper only
    assert np.array_equal(shown, world.camera.render(world.physics.client, "left", window))


def test_with_the_gui_a_float_path_move_sets_the_body_at_once_and_a_closed_world_stays_readable():
    with pytest.warns(RuntimeWarning, match="DISPLAY"):  # no display here: the GUI falls back to no window
        gui = DvrkWorld(WorldConfig(gui=True, camera_resolution=(320, 180)))
    plain = DvrkWorld(WorldConfig(camera_resolution=(320, 180)))
    q = ik.inverse_kinematics(kin.pose_from_euler(np.array([0.03, 0.04, -0.15]), 0.3, 0.1, -3.0))
    try:
        for world in (gui, plain):
            world.move_joints_floats(q.tolist(), noise_rng=np.random.default_rng(0))
        assert not gui._body_behind and plain._body_behind  # the GUI shows the body: it is set at once
        client, body = gui._physics.client, gui._robot.body_id
        np.testing.assert_allclose([client.getJointState(body, j)[0] for j in range(6)], gui.q_true, atol=1e-12)
    finally:
        gui.close()
        plain.close()
    assert plain.physics is not None and plain.robot is not None  # nothing left to set on a closed server


def test_the_tape_detector_shifts_the_right_image_only_and_the_camera_keeps_its_baseline():
    """With the detector's error off, a noisy detection is the exact centroid in whole pixels,
    the right one moved left by the shift; the printed circles are not moved; the endoscope
    renders with the baseline that goes with the shift."""
    shift = 3.0  # px at 1080p: one pixel at 640 wide
    noise = DetectionNoise(core_px=0.0, outlier_px=0.0, outlier_probability=0.0, right_shift_px=shift)
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(640, 360), marker_noise=noise))
    try:
        assert world.camera.baseline_m == true_baseline_m(shift)
        rng, checked = np.random.default_rng(0), 0
        for pose in _paper_poses(30, seed=5):
            world.move_to(pose)
            exact, seen = world.observe_marker(), world.observe_marker(noise_rng=rng)
            if not (exact.seen_both and seen.seen_both):
                continue
            checked += 1
            np.testing.assert_array_equal(seen.left_uv, whole_pixels(exact.left_uv, 640))
            np.testing.assert_array_equal(seen.right_uv, whole_pixels(exact.right_uv - [shift / 3, 0.0], 640))
        assert checked >= 5
        _, right = world.camera.project(grid_circle_centers())
        assert np.abs(np.array([d.right_uv for d in world.observe_grid()]) - right).max() < 0.5
    finally:
        world.close()


def test_the_tape_detector_finds_nothing_outside_its_search_boxes():
    """With the detector's error off, a detection whose whole pixels fall outside the authors'
    box is no detection, and one inside is the exact centroid in whole pixels; the exact path
    (no generator) searches the whole image."""
    noise = DetectionNoise(core_px=0.0, outlier_px=0.0, outlier_probability=0.0, search_boxes_px=paper.MARKER_SEARCH_BOXES_PX)
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(640, 360), marker_noise=noise))
    try:
        rng, verdicts = np.random.default_rng(0), []
        for pose in _paper_poses(60, seed=7):
            world.move_to(pose)
            exact, seen = world.observe_marker(), world.observe_marker(noise_rng=rng)
            if not exact.seen_left:
                continue
            inside = noise.searches("left", whole_pixels(exact.left_uv, 640), 640)
            verdicts.append(inside)
            if inside:
                np.testing.assert_array_equal(seen.left_uv, whole_pixels(exact.left_uv, 640))
            else:
                assert not seen.seen_left and not seen.seen_both
        assert any(verdicts) and not all(verdicts)  # the paper's poses put the tape on both sides of the box
    finally:
        world.close()


# --- what a world refuses, before anything changes ----------------------------------------


@pytest.fixture
def small_world():
    world = DvrkWorld(WorldConfig(camera_resolution=(320, 180)))
    yield world
    world.close()


def _state(world: DvrkWorld) -> tuple:
    return world.q_cmd.tobytes(), world.q_true.tobytes(), world.jaw_angle, world.clock.time_s


@pytest.mark.parametrize("jaw", [float("inf"), float("nan"), 100.0, -1.0, "0.2"])
def test_a_move_with_a_jaw_angle_out_of_range_is_refused_before_it_moves(small_world, jaw):
    q = ik.inverse_kinematics(_paper_poses(1)[0])
    before = _state(small_world)
    with pytest.raises(ValueError, match="jaw_angle_rad"):
        small_world.move_joints(q, jaw_angle_rad=jaw)
    with pytest.raises(ValueError, match="jaw_angle_rad"):
        small_world.reset_robot(q, jaw_angle_rad=jaw)
    assert _state(small_world) == before
    small_world.move_joints(q, jaw_angle_rad=0.3)  # still works
    assert small_world.jaw_angle == 0.3


def test_a_reset_outside_the_joint_limits_is_refused(small_world):
    before = _state(small_world)
    with pytest.raises(ik.UnreachablePoseError, match="outside the joint limits"):
        small_world.reset_robot(np.array([5.0, 0.0, 0.1, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="q must be finite"):
        small_world.reset_robot(np.array([np.nan, 0.0, 0.1, 0.0, 0.0, 0.0]))
    assert _state(small_world) == before


@pytest.mark.parametrize("state_id", [-1, 999, 1.5])
def test_restoring_a_physics_state_never_saved_is_a_clear_error(small_world, state_id):
    with pytest.raises(ValueError, match="state_id|no physics state 999"):
        small_world.restore_physics(state_id)  # -1 made PyBullet load a file and abort the process
    small_world.restore_physics(small_world.physics.client.saveState())


def test_visibility_from_a_camera_that_is_not_there_is_refused(small_world):
    with pytest.raises(ValueError, match="side must be one of"):
        small_world.marker_visible_fraction("middle")
