"""Perception on rendered pixels with OpenCV: the red marker and the printed circles.

Everything here works on RGB images (uint8, (height, width, 3)) and returns pixel
coordinates (u right, v down; pixel centres at integers, the OpenCV convention).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from dvrk_gym import paper
from dvrk_gym.sim.endoscope.camera import PixelWindow

RED_HUE_MAX = 8
"""Red hue lies in [0, RED_HUE_MAX] or [180 - RED_HUE_MAX, 180) in OpenCV's 0-180 hue scale."""
RED_MIN_SATURATION = 150
RED_MIN_VALUE = 50
MIN_MARKER_AREA_PX = 12
"""A red blob smaller than this (at any resolution) is noise, not the marker."""
MARKER_WINDOW_MARGIN_PX = 2
"""Pixels added around the marker's projected bounding box when rendering its window."""

DARK_MAX_VALUE = 45
"""A printed circle is darker than this (0-255) in grey level."""
MIN_CIRCULARITY = 0.75
"""4 pi area / perimeter^2 of a contour accepted as a printed circle (1 for a disc)."""


@dataclass(frozen=True)
class Blob:
    """A detected image region.

    Attributes:
        centroid: (u, v) of its pixel-mass centre, in pixels.
        area_px: its area in pixels.
        touches_border: whether it reaches the image edge (so it may be cut off).
    """

    centroid: np.ndarray
    area_px: float
    touches_border: bool


def check_rgb(rgb: np.ndarray) -> np.ndarray:
    """``rgb`` as a contiguous uint8 (h, w, 3) array, or a ValueError naming what it is.

    The thresholds here are on 0-255 levels: a float image in [0, 1] would pass through
    OpenCV's colour conversions and find nothing, silently.
    """
    image = np.asarray(rgb)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
        raise ValueError(f"expected an RGB image, uint8 (height, width, 3); got {image.dtype} {image.shape}")
    return np.ascontiguousarray(image)


def red_mask(rgb: np.ndarray) -> np.ndarray:
    """Binary mask (uint8, 0 or 255) of the strongly red pixels of an RGB image (uint8, (h, w, 3))."""
    hsv = cv2.cvtColor(check_rgb(rgb), cv2.COLOR_RGB2HSV)
    low = cv2.inRange(hsv, (0, RED_MIN_SATURATION, RED_MIN_VALUE), (RED_HUE_MAX, 255, 255))
    high = cv2.inRange(hsv, (180 - RED_HUE_MAX, RED_MIN_SATURATION, RED_MIN_VALUE), (180, 255, 255))
    return cv2.bitwise_or(low, high)


def median_kernel_px(width_px: int) -> int:
    """The authors' median kernel (9 px at 1920 wide) for an image width_px wide: odd, >= 1."""
    size = int(round(paper.MARKER_MEDIAN_KERNEL_PX * width_px / paper.ENDOSCOPE_RESOLUTION_PX[0]))
    return max(1, size - (1 - size % 2))


def detect_marker(rgb: np.ndarray, min_area_px: float = MIN_MARKER_AREA_PX, median_px: int = 1) -> Blob | None:
    """Find the red marker: the centroid of the largest red region, or None if not seen.

    Args:
        rgb: the image, uint8 (h, w, 3).
        min_area_px: the smallest region accepted as the marker, in pixels.
        median_px: odd size of the median filter run over the red mask first (1: none).
            The authors' detector median-filtered with 9 px at 1920 x 1080
            (:func:`median_kernel_px`): a sliver of tape seen edge-on, thinner than about
            half the kernel, vanishes, and with it the detection.
    """
    if median_px < 1 or median_px % 2 == 0:
        raise ValueError(f"median_px = {median_px}; expected an odd number of pixels >= 1")
    mask = red_mask(rgb)
    if median_px > 1:
        mask = cv2.medianBlur(mask, median_px)
    count, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count <= 1:
        return None
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    area = float(stats[largest, cv2.CC_STAT_AREA])
    if area < min_area_px:
        return None
    x, y, w, h = (int(stats[largest, k]) for k in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT))
    height, width = mask.shape
    touches = x == 0 or y == 0 or x + w >= width or y + h >= height
    return Blob(np.array(centroids[largest], dtype=float), area, touches)


def detect_marker_in_window(
    render: Callable[[PixelWindow], np.ndarray], image_size_px: tuple[int, int], corners_uv: np.ndarray
) -> Blob | None:
    """:func:`detect_marker` (with the authors' median kernel) in the window of an image of
    ``image_size_px`` (width, height) where a marker whose corners project to ``corners_uv``
    (N, 2) px can appear: their bounding box, plus ``MARKER_WINDOW_MARGIN_PX`` and the half
    kernel the median filter reads beyond the blob, cut to the image. ``render(window)``
    draws the window's pixels, which are the full image's there.

    Returns:
        The marker in full-image pixel coordinates; None when the window lies outside the
        image or holds no marker.
    """
    width, height = image_size_px
    margin = MARKER_WINDOW_MARGIN_PX + median_kernel_px(width) // 2
    low = np.maximum(np.floor(corners_uv.min(axis=0)).astype(int) - margin, 0)
    high = np.minimum(np.ceil(corners_uv.max(axis=0)).astype(int) + margin, [width - 1, height - 1])
    if np.any(high < low):  # entirely outside the image
        return None
    window = PixelWindow(int(low[0]), int(low[1]), int(high[0] - low[0] + 1), int(high[1] - low[1] + 1))
    blob = detect_marker(render(window), median_px=median_kernel_px(width))
    if blob is None:
        return None
    return Blob(blob.centroid + [window.u0, window.v0], blob.area_px, blob.touches_border)


def detect_circles(rgb: np.ndarray, min_area_px: float, max_area_px: float) -> np.ndarray:
    """Centroids of the dark, round regions of an image (the printed grid circles).

    Args:
        rgb: the image, uint8 (h, w, 3).
        min_area_px: the smallest accepted circle area, pixels.
        max_area_px: the largest accepted circle area, pixels.

    Returns:
        (N, 2) centroids (u, v) in pixels, sorted by v then u (top to bottom, left to right
        within rows of similar v).
    """
    grey = cv2.cvtColor(check_rgb(rgb), cv2.COLOR_RGB2GRAY)
    dark = (grey < DARK_MAX_VALUE).astype(np.uint8) * 255
    contours, _ = cv2.findContours(dark, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    found = []
    for contour in contours:
        area = cv2.contourArea(contour)
        perimeter = cv2.arcLength(contour, closed=True)
        if not (min_area_px <= area <= max_area_px) or perimeter <= 0:
            continue
        if 4.0 * np.pi * area / perimeter**2 < MIN_CIRCULARITY:
            continue
        found.append(_mask_centroid(dark, contour))
    if not found:
        return np.zeros((0, 2))
    points = np.array(found)
    return points[np.lexsort((points[:, 0], np.round(points[:, 1] / 10.0)))]


def _mask_centroid(mask: np.ndarray, contour: np.ndarray) -> np.ndarray:
    """Pixel-mass centroid of the mask inside one contour (more exact than the polygon's)."""
    x, y, w, h = cv2.boundingRect(contour)
    local = np.zeros((h, w), np.uint8)
    cv2.drawContours(local, [contour - [x, y]], -1, 255, thickness=cv2.FILLED)
    local &= mask[y : y + h, x : x + w]
    m = cv2.moments(local, binaryImage=True)
    return np.array([x + m["m10"] / m["m00"], y + m["m01"] / m["m00"]])


def match_to_expected(detected: np.ndarray, expected: np.ndarray, max_distance_px: float) -> np.ndarray:
    """Assign detections to expected points, nearest first.

    Args:
        detected: (N, 2) detected pixel positions.
        expected: (M, 2) where each of M known things should appear, pixels.
        max_distance_px: a detection farther than this from every expected point is ignored.

    Returns:
        (M, 2) the detection matched to each expected point, NaN where none was.
    """
    matched = np.full((len(expected), 2), np.nan)
    if len(detected) == 0:
        return matched
    distances = np.linalg.norm(expected[:, None, :] - detected[None, :, :], axis=2)
    used: set[int] = set()
    for flat in np.argsort(distances, axis=None):
        i, j = np.unravel_index(flat, distances.shape)
        if distances[i, j] > max_distance_px:
            break
        if np.isnan(matched[i, 0]) and j not in used:
            matched[i] = detected[j]
            used.add(int(j))
    return matched
