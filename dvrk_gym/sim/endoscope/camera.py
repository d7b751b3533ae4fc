"""Rectified stereo endoscope: projection, triangulation and PyBullet rendering.

Frames:
    * world: the robot base frame (metres, z up).
    * camera: OpenCV convention (x right, y down, z forward along the optical
      axis), origin at the LEFT camera's optical centre. The right camera is the
      left one translated by ``+baseline`` along the left camera's x axis.

Pixel convention: OpenCV, i.e. pixel centres at integer coordinates, row 0 at
the top of the image. PyBullet's TinyRenderer samples column ``i`` at viewport
coordinate ``x = i`` (no half-pixel offset) and flips the image vertically so
that output row ``r`` is sampled at viewport ``y = H - 1 - r``; the projection
matrix below compensates for both so that rendered pixels agree with
:meth:`StereoCamera.project` (verified in ``tests/test_camera.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
import pybullet
from scipy.spatial.transform import Rotation

from dvrk_gym import paper
from dvrk_gym.sim import identified
from dvrk_gym.sim.endoscope.baseline import PAPER_BASELINE_M
from dvrk_gym.utils.checks import check_float

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient

WORKSPACE_CENTER_M = (0.040, 0.042, -0.164)
# Where each renderer samples pixel (u, v) relative to the OpenCV pixel centre, as offsets
# (u, v) added before normalising to NDC. TinyRenderer: measured, see the module doc.
# OpenGL (the EGL renderer) samples pixel centres, at half-integers, and flips the rows
# when reading them back (measured on rendered spheres: tests/test_display.py).
_SAMPLE_OFFSETS_PX = {"tiny": (0.0, 1.0), "opengl": (0.5, 0.5)}
RENDERERS = tuple(_SAMPLE_OFFSETS_PX)
"""The renderers a projection matrix can be made for: PyBullet's TinyRenderer and OpenGL (EGL)."""
# OpenCV camera frame -> OpenGL camera frame (y up, looking along -z).
_CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
_SIDES = ("left", "right")


def _check_side(side: object) -> None:
    if side not in _SIDES:
        raise ValueError(f"side must be one of {_SIDES}, got {side!r}")


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of one camera of the rectified pair.

    Attributes:
        width: Image width in pixels.
        height: Image height in pixels.
        fx: Horizontal focal length in pixels.
        fy: Vertical focal length in pixels.
        cx: Principal point column in pixels (pixel centres at integers).
        cy: Principal point row in pixels (pixel centres at integers).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                raise ValueError(f"CameraIntrinsics.{name} must be a positive int, got {value!r}")
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"CameraIntrinsics.{name} must be finite and > 0 px, got {value!r}")
        for name in ("cx", "cy"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"CameraIntrinsics.{name} must be finite, got {getattr(self, name)!r}")

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """Return the intrinsics of the same camera resampled to ``width`` x ``height`` px.

        Focal lengths scale by the size ratio; principal points map as
        ``(c + 0.5) * s - 0.5`` because pixel centres sit at integers.
        """
        probe = CameraIntrinsics(width, height, 1.0, 1.0, 0.0, 0.0)  # validates the size
        sx = probe.width / self.width
        sy = probe.height / self.height
        return CameraIntrinsics(
            width,
            height,
            self.fx * sx,
            self.fy * sy,
            (self.cx + 0.5) * sx - 0.5,
            (self.cy + 0.5) * sy - 0.5,
        )


PAPER_INTRINSICS = CameraIntrinsics(
    *paper.ENDOSCOPE_RESOLUTION_PX, paper.ENDOSCOPE_FOCAL_PX, paper.ENDOSCOPE_FOCAL_PX, *paper.ENDOSCOPE_PRINCIPAL_POINT_PX
)
"""The authors' rectified cameras (their ROS camera files): 1920 x 1080, f = 2144.06 px."""


@dataclass(frozen=True)
class PixelWindow:
    """Sub-rectangle of the full image; pixel (u0, v0) is its top-left (full-image indices)."""

    u0: int
    v0: int
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("u0", "v0", "width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"PixelWindow.{name} must be an int, got {value!r}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"PixelWindow size must be positive, got {self.width}x{self.height}")


def default_camera_pose() -> np.ndarray:
    """Return T_world_leftcam (4x4, metres): the endoscope's pose identified from the authors' rows.

    :data:`dvrk_gym.sim.identified.CAMERA`: about 0.18 m above the workspace, looking down
    about 10 degrees from the vertical.
    """
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(identified.CAMERA.rotation_vector).as_matrix()
    pose[:3, 3] = identified.CAMERA.position_base_m
    return pose


def rgba_to_rgb(pixels, width: int, height: int) -> np.ndarray:
    """PyBullet's RGBA pixels (any array or sequence of ``height * width * 4`` bytes) as an
    (height, width, 3) uint8 RGB image. OpenCV drops the alpha channel some 25x faster than a
    strided numpy copy (55 ms against 2 ms for 1920 x 1080, measured), with the same bytes."""
    return cv2.cvtColor(np.asarray(pixels, dtype=np.uint8).reshape(height, width, 4), cv2.COLOR_RGBA2RGB)


def _as_points(points: np.ndarray, dims: int, name: str) -> np.ndarray:
    """Validate (N, dims) or (dims,) finite input and return it as float (N, dims)."""
    array = np.asarray(points, dtype=float)
    if array.ndim == 1:
        array = array[None, :]
    if array.ndim != 2 or array.shape[1] != dims:
        raise ValueError(f"{name} must have shape (N, {dims}) or ({dims},), got {np.shape(points)}")
    bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
    if bad.size:
        raise ValueError(f"{name} has non-finite values in row(s) {bad.tolist()}")
    return array


class StereoCamera:
    """Rectified stereo endoscope (same rotation and intrinsics for both cameras).

    Args:
        intrinsics: Intrinsics of each camera (pixels).
        baseline_m: Distance between the optical centres in metres (> 0): what the
            cameras see.
        calibrated_baseline_m: The baseline :meth:`triangulate` assumes, metres (> 0; None:
            baseline_m). A stereo calibration that got it wrong scales every triangulated
            position by calibrated_baseline_m / baseline_m.
        pose: T_world_leftcam (4x4, metres); defaults to :func:`default_camera_pose`.
        near_m: Near clipping plane for rendering, metres.
        far_m: Far clipping plane for rendering, metres.
    """

    def __init__(
        self,
        intrinsics: CameraIntrinsics = PAPER_INTRINSICS,
        baseline_m: float = PAPER_BASELINE_M,
        pose: np.ndarray | None = None,
        *,
        calibrated_baseline_m: float | None = None,
        near_m: float = 0.01,
        far_m: float = 1.0,
    ) -> None:
        if not isinstance(intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics must be CameraIntrinsics, got {type(intrinsics).__name__}")
        baseline_m = check_float("baseline_m", baseline_m, low=0.0, low_open=True, unit="m")
        calibrated_baseline_m = baseline_m if calibrated_baseline_m is None else calibrated_baseline_m
        calibrated_baseline_m = check_float("calibrated_baseline_m", calibrated_baseline_m, low=0.0, low_open=True, unit="m")
        near_m = check_float("near_m", near_m, low=0.0, low_open=True, unit="m")
        far_m = check_float("far_m", far_m, low=near_m, low_open=True, unit="m")
        pose = default_camera_pose() if pose is None else np.array(pose, dtype=float)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"pose must be a finite 4x4 matrix, got shape {pose.shape}")
        rotation = pose[:3, :3]
        if (
            not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6)
            or np.linalg.det(rotation) <= 0
            or not np.allclose(pose[3], [0, 0, 0, 1])
        ):
            raise ValueError("pose must be a rigid transform (orthonormal rotation, det +1)")
        self.intrinsics = intrinsics
        self.baseline_m = float(baseline_m)
        self.calibrated_baseline_m = float(calibrated_baseline_m)
        self.near_m = float(near_m)
        self.far_m = float(far_m)
        self._pose = pose
        self._pose.flags.writeable = False
        self._cam_from_world = np.linalg.inv(pose)
        self._cam_from_world_floats = self._cam_from_world[:3].tolist()

    @property
    def depth_scale(self) -> float:
        """Triangulated positions over true ones: calibrated_baseline_m / baseline_m (1: a right calibration)."""
        return self.calibrated_baseline_m / self.baseline_m

    @property
    def pose(self) -> np.ndarray:
        """T_world_leftcam (4x4, read-only view, metres)."""
        return self._pose

    def to_camera_frame(self, points_world: np.ndarray) -> np.ndarray:
        """Map world points (N, 3) or (3,) in metres to the left camera frame, (N, 3) m."""
        points = _as_points(points_world, 3, "points_world")
        return points @ self._cam_from_world[:3, :3].T + self._cam_from_world[:3, 3]

    def to_world(self, points_cam: np.ndarray) -> np.ndarray:
        """Map left-camera-frame points (N, 3) or (3,) in metres to the world frame, (N, 3) m."""
        points = _as_points(points_cam, 3, "points_cam")
        return points @ self._pose[:3, :3].T + self._pose[:3, 3]

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points (N, 3) or (3,) in metres to (left_uv, right_uv), each (N, 2) px."""
        return self.project_camera_frame(self.to_camera_frame(points_world))

    def project_camera_frame(self, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project left-camera-frame points (N, 3) m to (left_uv, right_uv), each (N, 2) px.

        Raises:
            ValueError: If a point is not strictly in front of the camera (z <= 0).
        """
        points = _as_points(points_cam, 3, "points_cam")
        behind = np.flatnonzero(points[:, 2] <= 0)
        if behind.size:
            raise ValueError(f"points_cam row(s) {behind.tolist()} are not in front of the camera (z <= 0)")
        k = self.intrinsics
        x, y, z = points.T
        v = k.fy * y / z + k.cy
        left = np.stack([k.fx * x / z + k.cx, v], axis=1)
        right = np.stack([k.fx * (x - self.baseline_m) / z + k.cx, v], axis=1)
        return left, right

    def triangulate(self, left_uv: np.ndarray, right_uv: np.ndarray) -> np.ndarray:
        """Triangulate matched pixels (N, 2) of the rectified pair into the LEFT camera frame.

        As the authors did (``camera_pixels_to_camera_coords`` in their code, ROS's
        ``StereoCameraModel.projectPixelTo3d``): the disparity is the distance between the
        left and the right pixel, ``d = |left - right|``, so a row mismatch adds to it;
        depth is ``z = fx * calibrated_baseline_m / d`` and the left pixel gives x and y.
        For a pair on the same row, and a calibration that got the baseline right, this is
        the exact inverse of :meth:`project_camera_frame`.

        Returns:
            (N, 3) positions in metres, left camera frame.

        Raises:
            ValueError: On shape mismatch, non-finite input or non-positive disparity.
        """
        left = _as_points(left_uv, 2, "left_uv")
        right = _as_points(right_uv, 2, "right_uv")
        if left.shape != right.shape:
            raise ValueError(f"left_uv and right_uv shapes differ: {left.shape} vs {right.shape}")
        bad = np.flatnonzero(left[:, 0] - right[:, 0] <= 0)
        if bad.size:
            raise ValueError(f"non-positive disparity in row(s) {bad.tolist()}: {(left[bad, 0] - right[bad, 0]).tolist()} px")
        k = self.intrinsics
        z = k.fx * self.calibrated_baseline_m / np.linalg.norm(left - right, axis=1)
        x = (left[:, 0] - k.cx) * z / k.fx
        y = (left[:, 1] - k.cy) * z / k.fy
        return np.stack([x, y, z], axis=1)

    def project_point_floats(self, point: list[float]) -> tuple[float, float, float]:
        """(left u, v, right u) px of one finite world point (3,) m (not checked; the right v is
        the left's), in Python floats: a few ulps from :meth:`project`; ValueError, as there,
        if the point is not in front of the camera."""
        (r0, r1, r2), k = self._cam_from_world_floats, self.intrinsics
        x, y, z = (r[0] * point[0] + r[1] * point[1] + r[2] * point[2] + r[3] for r in (r0, r1, r2))
        if z <= 0:
            raise ValueError("points_cam row(s) [0] are not in front of the camera (z <= 0)")
        return k.fx * x / z + k.cx, k.fy * y / z + k.cy, k.fx * (x - self.baseline_m) / z + k.cx

    def triangulate_floats(self, left: tuple[float, float], right: tuple[float, float]) -> list[float]:
        """:meth:`triangulate` of one pair of finite pixels (u, v) (not checked), in floats:
        the same numbers; ValueError on a non-positive disparity, as there."""
        k, du, dv = self.intrinsics, left[0] - right[0], left[1] - right[1]
        if du <= 0:
            raise ValueError(f"non-positive disparity in row(s) [0]: [{du}] px")
        z = k.fx * self.calibrated_baseline_m / math.sqrt(du * du + dv * dv)
        return [(left[0] - k.cx) * z / k.fx, (left[1] - k.cy) * z / k.fy, z]

    def optical_centre(self, side: str) -> np.ndarray:
        """Where the ``side`` ("left" or "right") camera's optical centre is, (3,) world frame, m."""
        _check_side(side)
        return self.pose[:3, 3] + (self.baseline_m * self.pose[:3, 0] if side == "right" else 0.0)

    def view_matrix(self, side: str) -> list[float]:
        """OpenGL view matrix (world -> GL eye) of ``side``, column-major list of 16 floats."""
        _check_side(side)
        cam_from_world = self._cam_from_world.copy()
        if side == "right":
            cam_from_world[0, 3] -= self.baseline_m
        return (_CV_TO_GL @ cam_from_world).flatten(order="F").tolist()

    def projection_matrix(self, window: PixelWindow | None = None, renderer: str = "tiny") -> list[float]:
        """OpenGL projection matrix, column-major list of 16 floats.

        With ``window`` the frustum is the off-centre sub-frustum covering exactly
        that window's pixels (principal point shifted by (u0, v0)). ``renderer`` ("tiny"
        for PyBullet's TinyRenderer, "opengl" for its EGL renderer) sets where pixels are
        sampled, so that either renderer's pixels agree with :meth:`project`.
        """
        if renderer not in _SAMPLE_OFFSETS_PX:
            raise ValueError(f"renderer must be one of {RENDERERS}, got {renderer!r}")
        k = self.intrinsics
        if window is None:
            window = PixelWindow(0, 0, k.width, k.height)
        self._check_window(window)
        w, h = window.width, window.height
        offset_u, offset_v = _SAMPLE_OFFSETS_PX[renderer]
        cx = k.cx - window.u0 + offset_u
        cy = k.cy - window.v0 + offset_v
        n, f = self.near_m, self.far_m
        proj = np.zeros((4, 4))
        proj[0, 0] = 2.0 * k.fx / w
        proj[0, 2] = 1.0 - 2.0 * cx / w
        proj[1, 1] = 2.0 * k.fy / h
        proj[1, 2] = 2.0 * cy / h - 1.0
        proj[2, 2] = -(f + n) / (f - n)
        proj[2, 3] = -2.0 * f * n / (f - n)
        proj[3, 2] = -1.0
        return proj.flatten(order="F").tolist()

    def render(self, client: BulletClient, side: str, window: PixelWindow | None = None) -> np.ndarray:
        """Render ``side`` (or only ``window`` of it) with PyBullet's TinyRenderer.

        Args:
            client: A ``pybullet_utils.bullet_client.BulletClient``.
            side: "left" or "right".
            window: Sub-rectangle to render; must lie inside the image (see
                :meth:`window_around` for clipping).

        Returns:
            (h, w, 3) uint8 RGB image (full image, or the window's pixels). A window
            matches the same pixels of a full-frame render except for ~1e-6 of
            pixels (+-1 grey level of shading rounding, or rare coverage ties on
            triangle edges).
        """
        k = self.intrinsics
        w, h = (k.width, k.height) if window is None else (window.width, window.height)
        result = client.getCameraImage(
            w,
            h,
            viewMatrix=self.view_matrix(side),
            projectionMatrix=self.projection_matrix(window),
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        return rgba_to_rgb(result[2], w, h)

    def window_around(self, uv: np.ndarray, half_size_px: int) -> PixelWindow:
        """Window of ``2 * half_size_px + 1`` px centred on the pixel nearest ``uv``, clipped to the image.

        Raises:
            ValueError: If ``uv`` is not finite, ``half_size_px`` < 0, or the window
                lies entirely outside the image.
        """
        centre = _as_points(uv, 2, "uv")
        if centre.shape[0] != 1:
            raise ValueError(f"uv must be a single (2,) pixel, got shape {np.shape(uv)}")
        if isinstance(half_size_px, bool) or not isinstance(half_size_px, (int, np.integer)) or half_size_px < 0:
            raise ValueError(f"half_size_px must be an int >= 0, got {half_size_px!r}")
        u, v = np.floor(centre[0] + 0.5).astype(int)
        u_lo, v_lo = max(u - half_size_px, 0), max(v - half_size_px, 0)
        u_hi = min(u + half_size_px, self.intrinsics.width - 1)
        v_hi = min(v + half_size_px, self.intrinsics.height - 1)
        if u_hi < u_lo or v_hi < v_lo:
            raise ValueError(f"window around uv={centre[0].tolist()} lies entirely outside the image")
        return PixelWindow(int(u_lo), int(v_lo), int(u_hi - u_lo + 1), int(v_hi - v_lo + 1))

    def _check_window(self, window: PixelWindow) -> None:
        """Raise ValueError unless ``window`` lies fully inside the image."""
        k = self.intrinsics
        if window.u0 < 0 or window.v0 < 0 or window.u0 + window.width > k.width or window.v0 + window.height > k.height:
            raise ValueError(f"{window} is not inside the {k.width}x{k.height} image; clip it first (window_around)")
