"""Fragments seen by the stereo endoscope: colour segmentation, contours, ellipse fits, stereo.

Both kinds of fragment are saturated colours (beige seeds, dark brown raisins) on white
paper printed with black circles, so they are segmented by saturation and brightness,
not darkness: paper and circles are grey (saturation under 10 of 255), while a seed is
about 70 and a raisin about 165 even in shade (measured on renders; see the tests). The
red marker and the blue receptacle are left out by hue.

Rendering the whole frame at the paper's 1920 x 1080 is slow (about 0.5 s a side on a
quiet core, twice that on a shared one), so :class:`FragmentObserver` looks in two passes:

1. a coarse render (a quarter of the resolution in each direction) of the paper's part of
   the image only, where the blobs are found and matched between the two images;
2. for each blob, a window of the camera's own resolution around it
   (:meth:`StereoCamera.render` with a window gives exactly the full frame's pixels
   there), where its contour is measured: the centroid for triangulation, and
   ``cv2.fitEllipse`` for the major axis' angle.

Nothing but pixels and the workspace's known layout (where the paper is) is used; the
result is that of the full-resolution search over the paper for any fragment that the
coarse pass sees (a fragment is at least 400 coarse pixels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from dvrk_gym.sim.endoscope.camera import PixelWindow, StereoCamera
from dvrk_gym.sim.endoscope.detection import RED_HUE_MAX, check_rgb
from dvrk_gym.sim.endoscope.noise import PixelNoise
from dvrk_gym.sim.physics.scene import PHANTOM_SIZE_M, WORKSPACE_CENTER_M

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient

MAX_HUE = 40
"""Fragment hues lie between the marker's red (up to RED_HUE_MAX) and this, on OpenCV's 0-180
scale: a raisin is about 12, a seed about 21; the blue receptacle (about 110) is left out."""
MIN_SATURATION = 40
"""A fragment pixel is at least this saturated (OpenCV's 0-255 scale); paper and circles are under 10."""
MIN_VALUE = 40
"""... and at least this bright (0-255): the printed circles are about 8."""
MIN_FRAGMENT_AREA_M2 = 2.0e-5
"""The smallest blob taken for a fragment, in the paper plane, m^2 (the smallest fragment
drawn is about 8 x 3 mm = 1.9e-5 m^2 of ellipse; the tool's edges and slivers are smaller)."""
COARSE_SCALE = 4
"""The coarse pass renders at 1/COARSE_SCALE of the resolution in each direction, or less
reduced where that would make it narrower than :data:`MIN_FRAGMENT_IMAGE_WIDTH_PX` (images
under 320 px wide)."""
MIN_FRAGMENT_IMAGE_WIDTH_PX = 80
"""The narrowest image, pixels, in which the fragments are all found; the coarse pass is never
narrower. Measured over 10 seeded Debridement-v0 resets of 8 fragments: 80/80 seeds and 80/80
raisins seen in 80 px wide images, and with coarse passes 80 px wide (at 1/4 of 320, 1/2 of
160); at 64 px, 80/80 seeds but 73/80 raisins, in both; at 48 px, fewer still. Before the
coarse pass kept this width (a quarter of every size), 128 px saw 0-2 fragments of 8."""
WINDOW_MARGIN_PX = 6
"""Full-resolution pixels added around a blob's scaled coarse bounding box."""
PAPER_INSET_M = 0.001
"""Blobs must have their centre this far inside the paper's edges, metres."""
DEPTH_RANGE_M = (0.12, 0.30)
"""Depths (camera z) a fragment can be seen at, metres: bounds the disparity searched."""
MAX_ROW_DIFFERENCE_PX = 3.0
"""Most a blob's row may differ between the rectified images (coarse pixels)."""
MAX_FRAGMENTS = 8


@dataclass(frozen=True)
class FragmentBlob:
    """A fragment's region in one image.

    Attributes:
        centroid: (u, v) of its pixel-mass centre, pixels (full resolution).
        angle_rad: the angle of the fitted ellipse's major axis in the image, from +u
            towards +v (down), radians in [-pi/2, pi/2).
        axes_px: (major, minor) full axis lengths of the fitted ellipse, pixels.
        area_px: its area, pixels.
        touches_border: whether it reaches the edge of the image (may be cut off).
    """

    centroid: np.ndarray
    angle_rad: float
    axes_px: tuple[float, float]
    area_px: float
    touches_border: bool


@dataclass(frozen=True)
class FragmentDetection:
    """One fragment seen by both cameras.

    Attributes:
        left: its blob in the left image.
        right: its blob in the right image.
        camera_position: the triangulated centroids, (x, y, z) left camera frame, metres.
    """

    left: FragmentBlob
    right: FragmentBlob
    camera_position: np.ndarray

    @property
    def image_angle_rad(self) -> float:
        """The major axis' angle in the left image, radians in [-pi/2, pi/2)."""
        return self.left.angle_rad


def fragment_mask(rgb: np.ndarray) -> np.ndarray:
    """Binary mask (uint8, 0 or 255) of the pixels that look like a fragment."""
    hsv = cv2.cvtColor(check_rgb(rgb), cv2.COLOR_RGB2HSV)
    return cv2.inRange(hsv, (RED_HUE_MAX + 1, MIN_SATURATION, MIN_VALUE), (MAX_HUE, 255, 255))


def _wrap_half_pi(angle: float) -> float:
    return (angle + math.pi / 2) % math.pi - math.pi / 2


def _blob(mask: np.ndarray, contour: np.ndarray) -> FragmentBlob:
    x, y, w, h = cv2.boundingRect(contour)
    local = np.zeros((h, w), np.uint8)
    cv2.drawContours(local, [contour - [x, y]], -1, 255, thickness=cv2.FILLED)
    local &= mask[y : y + h, x : x + w]
    m = cv2.moments(local, binaryImage=True)
    centroid = np.array([x + m["m10"] / m["m00"], y + m["m01"] / m["m00"]])
    if len(contour) >= 5:
        _, (d1, d2), angle_deg = cv2.fitEllipse(contour)
        # OpenCV's angle turns the first axis (length d1) from +u towards +v.
        major_deg = angle_deg if d1 >= d2 else angle_deg + 90.0
        axes = (max(d1, d2), min(d1, d2))
    else:  # too small to fit: the bounding box's long side
        major_deg, axes = (0.0, (w, h)) if w >= h else (90.0, (h, w))
    height, width = mask.shape
    touches = x == 0 or y == 0 or x + w >= width or y + h >= height
    return FragmentBlob(centroid, _wrap_half_pi(math.radians(major_deg)), (float(axes[0]), float(axes[1])), float(m["m00"]), touches)


def detect_fragments(rgb: np.ndarray, min_area_px: float) -> list[FragmentBlob]:
    """The fragment-coloured regions of an image of at least ``min_area_px`` pixels.

    Args:
        rgb: the image, uint8 (h, w, 3).
        min_area_px: the smallest region taken, pixels.

    Returns:
        Blobs in the image's pixel coordinates, largest first.
    """
    mask = fragment_mask(rgb)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    blobs = [_blob(mask, c) for c in contours if cv2.contourArea(c) >= min_area_px]
    return sorted(blobs, key=lambda b: -b.area_px)


def check_fragment_camera(name: str, resolution: tuple[int, int]) -> None:
    """Check that an endoscope of ``resolution`` (width, height), pixels, sees the fragments.

    Raises:
        ValueError: narrower than :data:`MIN_FRAGMENT_IMAGE_WIDTH_PX` (naming ``name``), where
            fragments would be lost without a word.
    """
    width, height = resolution
    if width < MIN_FRAGMENT_IMAGE_WIDTH_PX:
        raise ValueError(
            f"{name} {width} x {height} is too small for the endoscope to see the fragments: they need at least "
            f"{MIN_FRAGMENT_IMAGE_WIDTH_PX} px wide, e.g. 160 x 90 (render_resolution sets the picture alone)"
        )


def paper_corners(inset_m: float = 0.0) -> np.ndarray:
    """The paper's four corners, inset by ``inset_m``, (4, 3) base frame, metres (in order around)."""
    half = PHANTOM_SIZE_M[:2] / 2 - inset_m
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    corners = np.zeros((4, 3))
    corners[:, :2] = WORKSPACE_CENTER_M[:2] + signs * half
    corners[:, 2] = WORKSPACE_CENTER_M[2]
    return corners


class FragmentObserver:
    """Finds the fragments on the paper in both endoscope images (see the module notes).

    Args:
        camera: the stereo endoscope (its resolution is the one measured at).
        coarse_scale: how much smaller the coarse pass renders, per direction, at most (less
            where the coarse image would be narrower than :data:`MIN_FRAGMENT_IMAGE_WIDTH_PX`).
        pixel_noise_px: sd of the noise added to every centroid, at 1920 x 1080 (scaled
            with the resolution), pixels.
    """

    def __init__(self, camera: StereoCamera, coarse_scale: int = COARSE_SCALE, pixel_noise_px: float = 0.0) -> None:
        k = camera.intrinsics
        self.camera = camera
        self.scale = max(1, min(int(coarse_scale), k.width // MIN_FRAGMENT_IMAGE_WIDTH_PX))
        self.coarse = StereoCamera(
            k.scaled(max(16, k.width // self.scale), max(16, k.height // self.scale)),
            baseline_m=camera.baseline_m,
            pose=camera.pose,
            calibrated_baseline_m=camera.calibrated_baseline_m,
            near_m=camera.near_m,
            far_m=camera.far_m,
        )
        self.pixel_noise = PixelNoise(pixel_noise_px, k.width)
        px_per_m = k.fx / DEPTH_RANGE_M[1]  # at the far end of the depths: the smallest a fragment appears
        self.min_area_px = MIN_FRAGMENT_AREA_M2 * px_per_m**2
        outline = paper_corners()
        inside = paper_corners(PAPER_INSET_M)
        self._outline = dict(zip(("left", "right"), self.coarse.project(outline)))
        self._inside = dict(zip(("left", "right"), self.camera.project(inside)))
        fb = k.fx * camera.baseline_m
        self._disparity = (fb / DEPTH_RANGE_M[1], fb / DEPTH_RANGE_M[0])

    # ------------------------------------------------------------------ passes
    def _coarse_window(self, side: str) -> PixelWindow:
        k = self.coarse.intrinsics
        uv = self._outline[side]
        low = np.maximum(np.floor(uv.min(axis=0)).astype(int) - 1, 0)
        high = np.minimum(np.ceil(uv.max(axis=0)).astype(int) + 1, [k.width - 1, k.height - 1])
        return PixelWindow(int(low[0]), int(low[1]), int(high[0] - low[0] + 1), int(high[1] - low[1] + 1))

    def _coarse_blobs(self, client: BulletClient, side: str) -> list[tuple[FragmentBlob, np.ndarray]]:
        """Blobs of the coarse pass with their full-resolution bounding boxes (u0, v0, u1, v1)."""
        window = self._coarse_window(side)
        image = self.coarse.render(client, side, window)
        mask = fragment_mask(image)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        found = []
        min_area = self.min_area_px / self.scale**2
        for contour in contours:
            if cv2.contourArea(contour) < min_area:
                continue
            blob = _blob(mask, contour)
            x, y, w, h = cv2.boundingRect(contour)
            box = np.array([x + window.u0, y + window.v0, x + window.u0 + w, y + window.v0 + h], dtype=float)
            centre = blob.centroid + [window.u0, window.v0]
            found.append((FragmentBlob(centre, blob.angle_rad, blob.axes_px, blob.area_px, blob.touches_border), box * self.scale))
        return found

    def _fine_blob(self, client: BulletClient, side: str, box: np.ndarray, expected: np.ndarray) -> FragmentBlob | None:
        """The blob at full resolution in a window around ``box`` (full-resolution pixels)."""
        k = self.camera.intrinsics
        margin = WINDOW_MARGIN_PX + self.scale
        for _ in range(2):
            low = np.maximum(np.floor(box[:2]).astype(int) - margin, 0)
            high = np.minimum(np.ceil(box[2:]).astype(int) + margin, [k.width - 1, k.height - 1])
            window = PixelWindow(int(low[0]), int(low[1]), int(high[0] - low[0] + 1), int(high[1] - low[1] + 1))
            blobs = detect_fragments(self.camera.render(client, side, window), self.min_area_px)
            if not blobs:
                return None
            offset = np.array([window.u0, window.v0], dtype=float)
            best = min(blobs, key=lambda b: float(np.linalg.norm(b.centroid + offset - expected)))
            at_image_edge = window.u0 == 0 or window.v0 == 0 or high[0] == k.width - 1 or high[1] == k.height - 1
            if not best.touches_border or at_image_edge:
                return FragmentBlob(
                    best.centroid + offset, best.angle_rad, best.axes_px, best.area_px, best.touches_border and at_image_edge
                )
            margin *= 3  # cut off by the window: look wider once
        return FragmentBlob(best.centroid + offset, best.angle_rad, best.axes_px, best.area_px, True)

    def _match(self, left: list, right: list) -> list[tuple[int, int]]:
        """Pairs (i, j) of coarse left and right blobs on the same row at a plausible disparity."""
        d_low, d_high = (d / self.scale for d in self._disparity)
        candidates = []
        for i, (a, _) in enumerate(left):
            for j, (b, _) in enumerate(right):
                row = abs(a.centroid[1] - b.centroid[1])
                disparity = a.centroid[0] - b.centroid[0]
                if row <= MAX_ROW_DIFFERENCE_PX and d_low - 1 <= disparity <= d_high + 1:
                    size = abs(math.log(max(a.area_px, 1.0) / max(b.area_px, 1.0)))
                    candidates.append((row + 4.0 * size, i, j))
        pairs, used_left, used_right = [], set(), set()
        for _, i, j in sorted(candidates):
            if i not in used_left and j not in used_right:
                pairs.append((i, j))
                used_left.add(i)
                used_right.add(j)
        return pairs

    def on_paper(self, uv: np.ndarray, side: str = "left") -> bool:
        """Whether pixel ``uv`` (full resolution) of ``side``'s image shows the paper, inset by PAPER_INSET_M."""
        polygon = self._inside[side].astype(np.float32)
        return cv2.pointPolygonTest(polygon, (float(uv[0]), float(uv[1])), False) > 0

    # ------------------------------------------------------------------ public
    def observe(self, client: BulletClient, noise_rng: np.random.Generator | None = None) -> list[FragmentDetection]:
        """Every fragment on the paper that both cameras see, nearest the image's right edge first.

        Args:
            client: the physics client to render from.
            noise_rng: draws the configured pixel noise (None: exact centroids).

        Returns:
            At most MAX_FRAGMENTS detections, sorted by the left image's u, descending
            (the right of the image is the side of the receptacle).
        """
        left = self._coarse_blobs(client, "left")
        right = self._coarse_blobs(client, "right")
        detections = []
        for i, j in self._match(left, right):
            fine_left = self._fine_blob(client, "left", left[i][1], (left[i][0].centroid + 0.5) * self.scale - 0.5)
            fine_right = self._fine_blob(client, "right", right[j][1], (right[j][0].centroid + 0.5) * self.scale - 0.5)
            if fine_left is None or fine_right is None or not self.on_paper(fine_left.centroid, "left"):
                continue
            uv_left = self.pixel_noise.apply(fine_left.centroid, noise_rng)
            uv_right = self.pixel_noise.apply(fine_right.centroid, noise_rng)
            if uv_left[0] - uv_right[0] <= 0.0:
                continue
            position = self.camera.triangulate(uv_left, uv_right)[0]
            detections.append(FragmentDetection(fine_left, fine_right, position))
        detections.sort(key=lambda d: -d.left.centroid[0])
        return detections[:MAX_FRAGMENTS]
