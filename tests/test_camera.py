"""Tests for dvrk_gym.sim.endoscope.camera (geometry, GL matrices and TinyRenderer agreement) and .noise (pixel noise)."""

from __future__ import annotations

import cv2
import numpy as np
import pybullet
import pytest
from pybullet_utils import bullet_client

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity.instrument_model import real_pixels
from dvrk_gym.sim import identified
from dvrk_gym.sim.endoscope.baseline import TRUE_BASELINE_M, true_baseline_m
from dvrk_gym.sim.endoscope.camera import (
    PAPER_BASELINE_M,
    PAPER_INTRINSICS,
    WORKSPACE_CENTER_M,
    CameraIntrinsics,
    PixelWindow,
    StereoCamera,
    default_camera_pose,
)
from dvrk_gym.sim.endoscope.detection import detect_marker, median_kernel_px
from dvrk_gym.sim.endoscope.noise import DetectionNoise, PixelNoise, whole_pixels

SPHERE_RADIUS_M = 0.0015
CENTROID_TOL_PX = 0.3  # per point, any resolution; measured max 0.16 px (1920) / 0.23 px (640), silhouette digitisation
CENTROID_BIAS_TOL_PX = 0.1  # mean signed error (= 0.3 px x scale at 640x360); measured |mean| <= 0.04 px
TRIANGULATION_MEDIAN_TOL_M = 0.15e-3  # measured median ~0.1 mm
TRIANGULATION_MAX_TOL_M = 0.5e-3  # measured max 0.37 mm over 40 random points
# Window vs full-frame crop, measured over 2000 random windows (2.9e7 px): 6.8e-7 of pixels differ by 1 grey
# level (shading rounding) and 2.0e-7 by more (one box-edge pixel whose coverage test ties; it flips to the
# neighbouring face's colour, 86 levels). Everything else is bit-identical.
WINDOW_SHADING_TOL_LEVELS = 1
WINDOW_ANY_DIFF_FRACTION_TOL = 1e-4
WINDOW_EDGE_FLIP_FRACTION_TOL = 1e-5
CENTRE = np.asarray(WORKSPACE_CENTER_M)
_U, _, _VT = np.linalg.svd([[-0.965, -0.145, -0.219], [-0.115, 0.983, -0.144], [0.236, -0.114, -0.965]])
AIMED_POSE = np.eye(4)
AIMED_POSE[:3, :3] = _U @ _VT
AIMED_POSE[:3, 3] = CENTRE - 0.19 * AIMED_POSE[:3, 2]
"""A camera looking down about 15 degrees from the vertical with its optical axis through
the workspace centre at 0.19 m: every sphere below lies well inside its images, clear of
the shaft."""
SPHERE_OFFSETS_M = [
    (0.0, 0.0, 0.003),
    (-0.035, -0.035, 0.002),
    (0.035, 0.035, 0.01),
    (-0.035, 0.035, 0.02),
    (0.035, -0.035, 0.005),
    (0.01, -0.02, 0.015),
    (-0.02, 0.025, 0.004),
]


def red_centroid(image: np.ndarray) -> np.ndarray:
    """Centroid (u, v) in px of the red pixels of an RGB image."""
    r, g, b = (image[:, :, i].astype(int) for i in range(3))
    moments = cv2.moments(((r > 100) & (g < 80) & (b < 80)).astype(np.uint8), binaryImage=True)
    assert moments["m00"] > 0, "no red pixels found"
    return np.array([moments["m10"] / moments["m00"], moments["m01"] / moments["m00"]])


@pytest.fixture(scope="module")
def scene():
    """DIRECT client with a white box, black discs, a grey tool shaft and a red sphere; yields (client, sphere)."""
    client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    box = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=[0.0375, 0.0375, 0.005], rgbaColor=[1, 1, 1, 1])
    client.createMultiBody(0, baseVisualShapeIndex=box, basePosition=(CENTRE - [0, 0, 0.005]).tolist())
    disc = client.createVisualShape(pybullet.GEOM_CYLINDER, radius=0.002, length=0.0002, rgbaColor=[0, 0, 0, 1])
    for dx, dy in [(-0.026, -0.03), (0.0, -0.03), (0.026, 0.0), (-0.013, 0.02), (0.013, 0.03)]:
        client.createMultiBody(0, baseVisualShapeIndex=disc, basePosition=(CENTRE + [dx, dy, 0.0001]).tolist())
    shaft = client.createVisualShape(pybullet.GEOM_CYLINDER, radius=0.004, length=0.06, rgbaColor=[0.6, 0.6, 0.65, 1])
    client.createMultiBody(
        0,
        baseVisualShapeIndex=shaft,
        basePosition=(CENTRE + [0.065, 0.0, 0.02]).tolist(),
        baseOrientation=pybullet.getQuaternionFromEuler([0.0, 0.6, 0.3]),
    )
    red = client.createVisualShape(pybullet.GEOM_SPHERE, radius=SPHERE_RADIUS_M, rgbaColor=[1, 0, 0, 1])
    sphere = client.createMultiBody(0, baseVisualShapeIndex=red, basePosition=(CENTRE + [0, 0, 0.003]).tolist())
    yield client, sphere
    client.disconnect()


@pytest.fixture(scope="module")
def full_frames(scene):
    """Full 1920x1080 renders of both sides with the sphere at the workspace centre (+3 mm)."""
    client, sphere = scene
    client.resetBasePositionAndOrientation(sphere, (CENTRE + [0, 0, 0.003]).tolist(), [0, 0, 0, 1])
    camera = StereoCamera()
    return {side: camera.render(client, side) for side in ("left", "right")}


def test_intrinsics_scaling_keeps_pixel_centres_consistent() -> None:
    small = PAPER_INTRINSICS.scaled(640, 360)
    assert (small.width, small.height) == (640, 360)
    f, (cx, cy) = paper.ENDOSCOPE_FOCAL_PX, paper.ENDOSCOPE_PRINCIPAL_POINT_PX
    np.testing.assert_allclose([small.fx, small.fy, small.cx, small.cy], [f / 3, f / 3, (cx + 0.5) / 3 - 0.5, (cy + 0.5) / 3 - 0.5])
    points = np.array([[0.01, -0.02, 0.2], [-0.03, 0.01, 0.15]])
    full_uv, _ = StereoCamera(PAPER_INTRINSICS).project_camera_frame(points)
    small_uv, _ = StereoCamera(small).project_camera_frame(points)
    np.testing.assert_allclose(small_uv, (full_uv + 0.5) / 3.0 - 0.5, atol=1e-9)
    back = small.scaled(1920, 1080)
    np.testing.assert_allclose([back.fx, back.cx, back.cy], [f, cx, cy])


def test_project_triangulate_round_trip_on_random_points() -> None:
    camera = StereoCamera()
    rng = np.random.default_rng(0)
    z = rng.uniform(0.05, 0.6, 2000)
    points_cam = np.stack([rng.uniform(-0.4, 0.4, z.size) * z, rng.uniform(-0.25, 0.25, z.size) * z, z], axis=1)
    points_world = camera.to_world(points_cam)
    np.testing.assert_allclose(camera.to_camera_frame(points_world), points_cam, rtol=0, atol=1e-15)
    left, right = camera.project(points_world)
    recovered = camera.triangulate(left, right)
    expected = camera.to_camera_frame(points_world)
    assert np.max(np.abs(recovered - expected) / np.linalg.norm(expected, axis=1, keepdims=True)) < 1e-12


def test_right_camera_is_offset_by_baseline_along_x() -> None:
    camera = StereoCamera()
    points_cam = np.array([[0.0, 0.0, 0.19], [0.02, -0.01, 0.15], [-0.03, 0.02, 0.3]])
    left, right = camera.project_camera_frame(points_cam)
    np.testing.assert_allclose(left[:, 1], right[:, 1])
    np.testing.assert_allclose(left[:, 0] - right[:, 0], PAPER_INTRINSICS.fx * PAPER_BASELINE_M / points_cam[:, 2])
    right_centre_world = camera.pose @ np.array([PAPER_BASELINE_M, 0.0, 0.0, 1.0])
    view_right = np.asarray(camera.view_matrix("right")).reshape(4, 4, order="F")
    np.testing.assert_allclose(view_right @ right_centre_world, [0, 0, 0, 1], atol=1e-15)


def test_default_pose_is_the_identified_one_above_the_workspace_and_sees_it() -> None:
    pose = default_camera_pose()
    np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(pose[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(pose[:3, 3], identified.CAMERA.position_base_m)
    # The paper: 7.5 in (19 cm) above the workspace; identified: 18 cm, 9.7 deg from the vertical.
    assert 0.17 < pose[2, 3] - CENTRE[2] < 0.20
    assert 5.0 < np.degrees(np.arccos(-pose[2, 2])) < 15.0
    # The real rows' detections span u 684-1422 px, v 75-798 px: the workspace is in view.
    left, right = StereoCamera(pose=pose).project(CENTRE + [[0.03, 0.03, 0.0], [-0.03, -0.03, 0.0]])
    for uv in (left, right):
        assert np.all((uv > 0) & (uv < [PAPER_INTRINSICS.width, PAPER_INTRINSICS.height]))


def test_triangulation_uses_the_distance_between_the_pixels_as_the_authors_did() -> None:
    # ROS's projectPixelTo3d with disparity |left - right|: a row mismatch deepens nothing but
    # shortens the depth; x and y come from the left pixel.
    camera = StereoCamera()
    left, right = np.array([[1000.0, 400.0]]), np.array([[930.0, 405.0]])
    z = PAPER_INTRINSICS.fx * PAPER_BASELINE_M / np.hypot(70.0, 5.0)
    expected = [(1000.0 - PAPER_INTRINSICS.cx) * z / PAPER_INTRINSICS.fx, (400.0 - PAPER_INTRINSICS.cy) * z / PAPER_INTRINSICS.fy, z]
    np.testing.assert_allclose(camera.triangulate(left, right)[0], expected)


def test_a_short_calibrated_baseline_scales_triangulated_positions() -> None:
    camera = StereoCamera(baseline_m=0.0065, calibrated_baseline_m=0.0060)
    point = np.array([[0.01, -0.02, 0.18]])
    np.testing.assert_allclose(camera.triangulate(*camera.project_camera_frame(point)), point * 0.0060 / 0.0065)


def test_gl_matrices_reproduce_projection_with_tinyrenderer_sampling() -> None:
    """TinyRenderer samples column i at viewport x = i and row r at viewport y = h - 1 - r."""
    camera = StereoCamera()
    points = CENTRE + np.random.default_rng(1).uniform(-0.03, 0.03, (50, 3))
    for window in (None, PixelWindow(700, 300, 64, 48)):
        w, h, u0, v0 = (1920, 1080, 0, 0) if window is None else (window.width, window.height, window.u0, window.v0)
        proj = np.asarray(camera.projection_matrix(window)).reshape(4, 4, order="F")
        for side, uv in zip(("left", "right"), camera.project(points)):
            view = np.asarray(camera.view_matrix(side)).reshape(4, 4, order="F")
            clip = (proj @ view @ np.c_[points, np.ones(len(points))].T).T
            ndc = clip[:, :2] / clip[:, 3:]
            pixels = np.stack([u0 + (ndc[:, 0] + 1) * w / 2, v0 + h - 1 - (ndc[:, 1] + 1) * h / 2], axis=1)
            np.testing.assert_allclose(pixels, uv, atol=1e-9)


def test_rendered_sphere_centroid_matches_projection_full_frame(full_frames) -> None:
    camera = StereoCamera()
    sphere_world = CENTRE + [0, 0, 0.003]
    centroids = {}
    for side, uv in zip(("left", "right"), camera.project(sphere_world)):
        centroids[side] = red_centroid(full_frames[side])
        assert np.linalg.norm(centroids[side] - uv[0]) < CENTROID_TOL_PX, side
    recovered = camera.to_world(camera.triangulate(centroids["left"], centroids["right"]))[0]
    assert np.linalg.norm(recovered - sphere_world) < TRIANGULATION_MAX_TOL_M


def test_window_render_equals_full_frame_crop(scene, full_frames) -> None:
    client, _ = scene
    camera = StereoCamera()
    rng = np.random.default_rng(2)
    windows = [
        PixelWindow(0, 0, 64, 64),
        PixelWindow(1920 - 65, 1080 - 47, 65, 47),
        PixelWindow(959, 539, 1, 1),
        PixelWindow(0, 500, 1920, 3),
        camera.window_around(camera.project(CENTRE)[0][0], 40),
    ]
    for size in (48, 64, 96, 128, 37):
        windows += [PixelWindow(int(rng.integers(0, 1920 - size)), int(rng.integers(0, 1080 - size)), size, size) for _ in range(4)]
    n_diff = n_flipped = n_total = 0
    for side in ("left", "right"):
        for window in windows:
            image = camera.render(client, side, window)
            assert image.shape == (window.height, window.width, 3) and image.dtype == np.uint8
            crop = full_frames[side][window.v0 : window.v0 + window.height, window.u0 : window.u0 + window.width]
            diff = np.abs(image.astype(int) - crop.astype(int)).max(axis=2)
            n_diff += int(np.count_nonzero(diff))
            n_flipped += int(np.count_nonzero(diff > WINDOW_SHADING_TOL_LEVELS))
            n_total += diff.size
    assert n_diff / n_total <= WINDOW_ANY_DIFF_FRACTION_TOL
    assert n_flipped / n_total <= WINDOW_EDGE_FLIP_FRACTION_TOL


@pytest.mark.parametrize("intrinsics", [PAPER_INTRINSICS, PAPER_INTRINSICS.scaled(640, 360)], ids=["1920", "640"])
def test_sphere_centroids_across_workspace_match_projection_and_triangulate(scene, intrinsics) -> None:
    """Full-res uses windows (validated above); 640x360 renders full frames."""
    client, sphere = scene
    camera = StereoCamera(intrinsics, pose=AIMED_POSE)
    scale = intrinsics.width / PAPER_INTRINSICS.width
    errors, depth_errors = [], []
    for offset in SPHERE_OFFSETS_M:
        point = CENTRE + offset
        client.resetBasePositionAndOrientation(sphere, point.tolist(), [0, 0, 0, 1])
        centroids = []
        for side, uv in zip(("left", "right"), camera.project(point)):
            window = camera.window_around(uv[0], 40) if scale == 1.0 else None
            origin = np.zeros(2) if window is None else np.array([window.u0, window.v0])
            centroids.append(red_centroid(camera.render(client, side, window)) + origin)
            errors.append(centroids[-1] - uv[0])
        recovered = camera.to_world(camera.triangulate(centroids[0], centroids[1]))[0]
        depth_errors.append(np.linalg.norm(recovered - point))
    errors = np.array(errors)
    assert np.linalg.norm(errors, axis=1).max() < CENTROID_TOL_PX
    assert np.all(np.abs(errors.mean(axis=0)) < CENTROID_BIAS_TOL_PX)
    if scale == 1.0:
        assert np.median(depth_errors) < TRIANGULATION_MEDIAN_TOL_M
        assert max(depth_errors) < TRIANGULATION_MAX_TOL_M


def test_window_around_clips_to_image() -> None:
    camera = StereoCamera()
    assert camera.window_around(np.array([959.6, 539.4]), 32) == PixelWindow(928, 507, 65, 65)
    assert camera.window_around(np.array([3.2, 1075.0]), 10) == PixelWindow(0, 1065, 14, 15)


def test_bad_inputs_raise_value_error(scene) -> None:
    client, _ = scene
    camera = StereoCamera()
    with pytest.raises(ValueError, match=r"row\(s\) \[1\]"):
        camera.triangulate(np.array([[100.0, 50.0], [100.0, 50.0]]), np.array([[90.0, 50.0], [105.0, 50.0]]))
    with pytest.raises(ValueError, match="disparity"):
        camera.triangulate(np.array([100.0, 50.0]), np.array([100.0, 50.0]))
    with pytest.raises(ValueError, match="non-finite"):
        camera.project(np.array([[0.04, np.nan, -0.16]]))
    with pytest.raises(ValueError, match="non-finite"):
        camera.triangulate(np.array([np.inf, 1.0]), np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="in front"):
        camera.project_camera_frame(np.array([0.0, 0.0, -0.1]))
    with pytest.raises(ValueError, match="shape"):
        camera.project(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="not inside"):
        camera.render(client, "left", PixelWindow(1900, 10, 64, 64))
    with pytest.raises(ValueError, match="not inside"):
        camera.projection_matrix(PixelWindow(-1, 0, 8, 8))
    with pytest.raises(ValueError, match="entirely outside"):
        camera.window_around(np.array([-100.0, 50.0]), 20)
    with pytest.raises(ValueError, match="side"):
        camera.view_matrix("centre")
    with pytest.raises(ValueError):
        PixelWindow(0, 0, 0, 10)
    with pytest.raises(ValueError):
        CameraIntrinsics(1920, 1080, -1.0, 2144.0, 959.5, 539.5)
    with pytest.raises(ValueError):
        CameraIntrinsics(1920, 1080, 2144.0, 2144.0, float("nan"), 539.5)
    with pytest.raises(ValueError):
        StereoCamera(baseline_m=0.0)
    with pytest.raises(ValueError, match="rigid"):
        StereoCamera(pose=np.diag([2.0, 1.0, 1.0, 1.0]))


# --- pixel noise ------------------------------------------------------------------------


@pytest.mark.parametrize("width_px, expected_sigma_px", [(1920, 1.5), (960, 0.75), (480, 0.375), (3840, 3.0)])
def test_pixel_noise_scales_with_the_image_width(width_px: int, expected_sigma_px: float) -> None:
    # The setting is in pixels of the paper's 1920-wide images: half the width, half the pixels.
    assert PixelNoise(1.5, width_px).sigma_px == expected_sigma_px
    assert PixelNoise(1.5, 960).sigma_px == 0.5 * PixelNoise(1.5, 1920).sigma_px


@pytest.mark.parametrize("uv_shape", [(2,), (1, 2)])
def test_pixel_noise_draws_two_normals_per_detection_in_call_order(uv_shape: tuple[int, ...]) -> None:
    noise = PixelNoise(2.0, 960)
    left, right = np.full(uv_shape, 100.0), np.full(uv_shape, 40.0)
    rng, explicit = np.random.default_rng(7), np.random.default_rng(7)
    noisy_left, noisy_right = noise.apply(left, rng), noise.apply(right, rng)
    np.testing.assert_array_equal(noisy_left, left + explicit.normal(0.0, 1.0, size=2))
    np.testing.assert_array_equal(noisy_right, right + explicit.normal(0.0, 1.0, size=2))
    assert noisy_left.shape == uv_shape
    assert rng.random() == explicit.random()  # nothing more was drawn


@pytest.mark.parametrize("noise, rng", [(PixelNoise(0.0, 640), np.random.default_rng(3)), (PixelNoise(1.0, 640), None)])
def test_no_pixel_noise_draws_nothing_and_returns_the_detection(noise: PixelNoise, rng: np.random.Generator | None) -> None:
    uv = np.array([12.5, 7.25])
    assert noise.apply(uv, rng) is uv
    if rng is not None:
        assert rng.random() == np.random.default_rng(3).random()


@pytest.mark.parametrize("sigma, width", [(-0.5, 1920), (float("nan"), 1920), (1.0, 0)])
def test_pixel_noise_rejects_a_negative_or_nan_sigma_and_an_empty_width(sigma: float, width: int) -> None:
    with pytest.raises(ValueError, match="sigma_px_at_1080p|width_px"):
        PixelNoise(sigma, width)


def test_whole_pixels_truncate_on_the_1080p_grid_at_any_resolution() -> None:
    np.testing.assert_array_equal(whole_pixels(np.array([[10.2, 20.9], [10.99, -0.4]]), 1920), [[10.0, 20.0], [10.0, -1.0]])
    # At 640 px wide a 1080p pixel is a third of a pixel: 10.2 px is 1080p pixel 31.6 -> 31.
    np.testing.assert_allclose(whole_pixels(np.array([10.2, 5.0]), 640), [(31 + 0.5) / 3 - 0.5, (16 + 0.5) / 3 - 0.5])


def test_detection_noise_draws_outliers_and_misses_at_their_rates() -> None:
    rng = np.random.default_rng(0)
    noise = DetectionNoise(core_px=1.0, outlier_px=5.0, outlier_probability=0.2, miss_probability=0.3)
    errors = np.array([noise.sample(rng) for _ in range(20000)])
    assert np.var(errors) == pytest.approx(0.8 * 1.0 + 0.2 * 25.0, rel=0.05)
    assert np.mean([noise.misses(rng) for _ in range(20000)]) == pytest.approx(0.3, abs=0.01)
    np.testing.assert_allclose(noise.sample(np.random.default_rng(1), 640) * 3, noise.sample(np.random.default_rng(1), 1920))
    assert not DetectionNoise(1.0, 1.0, 0.0).misses(rng)
    many = noise.sample_many(rng, (100, 200))  # the same mixture, drawn at once
    assert many.shape == (100, 200, 2)
    assert np.var(many) == pytest.approx(0.8 * 1.0 + 0.2 * 25.0, rel=0.05)
    # Beyond 3 px: 0.2% of the core's draws, 55% of the outliers'.
    assert np.mean(np.abs(many) > 3.0) == pytest.approx(0.8 * 0.0027 + 0.2 * 0.5485, abs=0.005)
    np.testing.assert_allclose(
        noise.sample_many(np.random.default_rng(1), (7,), 640) * 3, noise.sample_many(np.random.default_rng(1), (7,))
    )
    with pytest.raises(ValueError, match="miss_probability"):
        DetectionNoise(1.0, 1.0, 0.0, miss_probability=1.5)
    with pytest.raises(ValueError, match="core_px"):
        DetectionNoise(-1.0, 1.0, 0.0)


def test_the_median_filter_drops_a_sliver_but_keeps_the_tape() -> None:
    image = np.zeros((60, 60, 3), np.uint8)
    image[10:30, 10:30] = (220, 10, 10)  # the tape seen face-on: 20 x 20 px
    image[40:42, 5:55] = (220, 10, 10)  # a sliver two pixels thin, larger than the tape would need to be found
    assert detect_marker(image, median_px=1).area_px == 400
    found = detect_marker(image, median_px=median_kernel_px(1920))
    np.testing.assert_allclose(found.centroid, [19.5, 19.5], atol=0.5)
    sliver_only = image.copy()
    sliver_only[10:30, 10:30] = 0
    assert detect_marker(sliver_only, median_px=1) is not None and detect_marker(sliver_only, median_px=9) is None
    assert [median_kernel_px(w) for w in (1920, 960, 640, 320)] == [9, 3, 3, 1]
    with pytest.raises(ValueError, match="median_px"):
        detect_marker(image, median_px=4)


@pytest.mark.parametrize(
    "bad",
    [np.zeros((60, 60, 3), np.float32), np.zeros((60, 60, 4), np.uint8), np.zeros((60, 60), np.uint8), np.zeros((0, 60, 3), np.uint8)],
    ids=["float", "rgba", "grey", "empty"],
)
def test_the_detectors_refuse_an_image_that_is_not_uint8_rgb(bad: np.ndarray) -> None:
    from dvrk_gym.sim.endoscope.detection import detect_circles
    from dvrk_gym.sim.endoscope.fragment_detection import detect_fragments

    marker = np.zeros((60, 60, 3), np.uint8)
    marker[10:30, 10:30] = (220, 10, 10)
    assert detect_marker(marker) is not None  # the same scene as uint8 RGB is found
    for detect in (lambda im: detect_marker(im), lambda im: detect_circles(im, 1.0, 100.0), lambda im: detect_fragments(im, 1.0)):
        with pytest.raises(ValueError, match="uint8"):
            detect(bad)
    # The float image of the same marker in [0, 1] used to find nothing, silently.
    with pytest.raises(ValueError, match="float"):
        detect_marker(marker.astype(np.float32) / 255.0)


def test_the_right_image_shift_moves_the_right_centroid_left_and_draws_nothing() -> None:
    noise = DetectionNoise(core_px=1.0, outlier_px=5.0, outlier_probability=0.2, right_shift_px=2.5)
    np.testing.assert_array_equal(noise.shift("right"), [-2.5, 0.0])
    np.testing.assert_allclose(noise.shift("right", 640), [-2.5 / 3, 0.0])
    np.testing.assert_array_equal(noise.shift("left"), [0.0, 0.0])
    unshifted = DetectionNoise(core_px=1.0, outlier_px=5.0, outlier_probability=0.2)
    np.testing.assert_array_equal(noise.sample(np.random.default_rng(4)), unshifted.sample(np.random.default_rng(4)))
    with pytest.raises(ValueError, match="side"):
        noise.shift("middle")
    for bad in (float("nan"), 25.0, -25.0):
        with pytest.raises(ValueError, match="right_shift_px"):
            DetectionNoise(1.0, 1.0, 0.0, right_shift_px=bad)


@pytest.mark.parametrize("shift_px", [0.0, identified.TAPE_RIGHT_SHIFT_PX, 4.0])
def test_the_true_baseline_keeps_the_tape_where_the_rows_put_it(shift_px: float) -> None:
    """A tape at the rows' median depth, its disparity widened by the shift, triangulates (with
    the authors' baseline) at the identified depth scale times its depth, whatever the shift."""
    focal, depth = paper.ENDOSCOPE_FOCAL_PX, identified.TAPE_ROWS_DEPTH_M
    baseline = true_baseline_m(shift_px)
    seen_depth = focal * PAPER_BASELINE_M / (focal * baseline / depth + shift_px)
    assert seen_depth == pytest.approx(identified.CAMERA.depth_scale * depth, rel=1e-12)
    # What the shift does not touch (the printed circles) is seen at PAPER_BASELINE_M / baseline of its depth.
    assert PAPER_BASELINE_M / baseline > identified.CAMERA.depth_scale or shift_px == 0.0


def test_the_rows_depth_is_their_median_and_a_bad_shift_is_refused() -> None:
    X, _ = load_paper_phase1()
    assert pytest.approx(np.median(X[:, 2]) / identified.CAMERA.depth_scale, abs=1e-5) == identified.TAPE_ROWS_DEPTH_M
    assert true_baseline_m(identified.TAPE_RIGHT_SHIFT_PX) == TRUE_BASELINE_M
    for bad in (float("nan"), float("inf"), 100.0):
        with pytest.raises(ValueError, match="tape_right_shift_px"):
            true_baseline_m(bad)


def test_the_detector_searches_only_strictly_inside_its_boxes_on_the_1080p_grid() -> None:
    noise = DetectionNoise(core_px=1.0, outlier_px=5.0, outlier_probability=0.2, search_boxes_px=paper.MARKER_SEARCH_BOXES_PX)
    assert noise.searches("left", np.array([676.0, 51.0])) and noise.searches("left", np.array([1424.0, 799.0]))
    assert not noise.searches("left", np.array([675.0, 400.0])) and not noise.searches("left", np.array([1000.0, 800.0]))
    assert noise.searches("right", np.array([601.0, 76.0])) and not noise.searches("right", np.array([1350.0, 400.0]))
    # At other widths the whole pixels of the 1080p grid come back to it with rounding errors:
    # 676 and 1424 are inside, 675 and 1425 (the edges) are not, at any width.
    for width in (184, 200, 400, 640, 800, 1280, 1600):
        scale = 1920 / width
        u = (np.array([676.0, 1424.0, 675.0, 1425.0]) + 0.5) / scale - 0.5
        verdicts = [noise.searches("left", np.array([value, (300.0 + 0.5) / scale - 0.5]), width) for value in u]
        assert verdicts == [True, True, False, False], width
    unboxed = DetectionNoise(core_px=1.0, outlier_px=5.0, outlier_probability=0.2)
    assert unboxed.searches("left", np.array([-5.0, 5000.0]))
    np.testing.assert_array_equal(noise.sample(np.random.default_rng(4)), unboxed.sample(np.random.default_rng(4)))
    with pytest.raises(ValueError, match="side"):
        noise.searches("middle", np.array([700.0, 100.0]))
    bad_boxes = (
        ((0, 0, 10, 10),),
        ((0, 0, 10, 0), (0, 0, 10, 10)),
        ((0, 0, 10, float("nan")), (0, 0, 10, 10)),
        ((True, 0, 10, 10), (0, 0, 10, 10)),
        "box",
    )
    for bad in bad_boxes:
        with pytest.raises(ValueError, match="search_boxes_px"):
            DetectionNoise(core_px=1.0, outlier_px=1.0, outlier_probability=0.0, search_boxes_px=bad)  # type: ignore[arg-type]
    as_arrays = DetectionNoise(core_px=1.0, outlier_px=1.0, outlier_probability=0.0, search_boxes_px=np.array(paper.MARKER_SEARCH_BOXES_PX))  # type: ignore[arg-type]
    assert as_arrays.search_boxes_px == paper.MARKER_SEARCH_BOXES_PX and hash(as_arrays)  # stored as tuples, hashable


def test_every_real_rows_detection_lies_inside_the_authors_boxes() -> None:
    """The real rows are what the authors' detector kept, so their detections all lie inside its
    boxes (the left one exactly; the right one's u to within the row mismatch's share of the
    disparity, under a pixel) and reach close to the left box's right and bottom edges."""
    X, _ = load_paper_phase1()
    u, v, disparity = real_pixels(X).T
    (lu, lv, lw, lh), (ru, _, rw, _) = paper.MARKER_SEARCH_BOXES_PX
    assert np.all((lu < u) & (u < lu + lw) & (lv < v) & (v < lv + lh))
    assert u.max() > lu + lw - 5 and v.max() > lv + lh - 5
    assert np.all((ru - 1 < u - disparity) & (u - disparity < ru + rw))
