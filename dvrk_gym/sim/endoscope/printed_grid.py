"""The 35 printed circles as the endoscope sees them, detected once per scene and camera.

The grid does not move, so what the endoscope sees of it with the tool retracted depends
only on what is in the scene and on the camera. Every GridTouch env, Phase I collection
and demo reads it, and detecting it takes two full-frame renders (1.1 s at 1920 x 1080 on
one core, measured; a ``dvrk-gym reproduce --quick`` did it seven times in its two worker
processes). :func:`observe_printed_grid` therefore keeps the detections of every scene it
has seen, in this process, under a key that holds everything the detections depend on:
both view matrices, the projection, the image size, the baseline the triangulation
assumes, and a description of the scene from its owner (the world: the DH table its arm's
body is built from, given only while its physics holds nothing but its own bodies; the
presets' instruments differ in their cables, not their links, so they share it). Same key, same pixels (TinyRenderer is
deterministic), same detections, bit for bit. A scene that cannot be described that way
(key None) is detected afresh every time.

Windows around each expected circle are not used instead: measured on 90 instruments and
resolutions, they gave centroids that differed from the full frame's in their last bits
(the window's offset added back), at 1920 x 1080 one of them by 0.011 px (a pixel shaded
differently), and they were no faster at 1920 x 1080 when large enough to hold every circle.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable

import numpy as np

from dvrk_gym import paper
from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.sim.endoscope.detection import Blob, detect_circles, match_to_expected
from dvrk_gym.sim.endoscope.stereo import StereoDetection, stereo_detection
from dvrk_gym.sim.physics.scene import CIRCLE_RADIUS_M, grid_circle_centers

__all__ = ["CACHE_SIZE", "clear_cache", "detect_printed_grid", "observe_printed_grid"]

CACHE_SIZE = 64
"""Scenes whose detections are kept (least recently used dropped first); 35 detections each."""
NOMINAL_DEPTH_M = paper.ENDOSCOPE_HEIGHT_M
"""The depth at which a circle's expected radius in pixels is taken, metres: the endoscope's height."""

_CACHE: OrderedDict[Hashable, tuple[StereoDetection, ...]] = OrderedDict()
_LOCK = threading.Lock()  # worlds in several threads: the cache's reads and writes, not the renders


def detect_printed_grid(camera: StereoCamera, left: np.ndarray, right: np.ndarray) -> tuple[StereoDetection, ...]:
    """Detect the 35 circles in a left and a right image (RGB uint8), in grid order.

    Each detection goes to the circle it belongs to by where that circle should appear
    (within a circle's radius), as a person reading the grid would; a circle that was not
    found gets NaN. Circles count if their area is 0.4 to 2 times that of a circle at
    :data:`NOMINAL_DEPTH_M`.
    """
    k = camera.intrinsics
    radius_px = CIRCLE_RADIUS_M * k.fx / NOMINAL_DEPTH_M
    area = math.pi * radius_px**2
    expected_sides = camera.project(grid_circle_centers())
    found = []
    for image, expected in zip((left, right), expected_sides):
        detected = detect_circles(image, min_area_px=0.4 * area, max_area_px=2.0 * area)
        found.append(match_to_expected(detected, expected, max_distance_px=radius_px))
    return tuple(stereo_detection(camera, _blob_or_none(left_uv), _blob_or_none(right_uv)) for left_uv, right_uv in zip(*found))


def observe_printed_grid(
    camera: StereoCamera, scene_key: Hashable | None, render_both: Callable[[], tuple[np.ndarray, np.ndarray]]
) -> tuple[StereoDetection, ...]:
    """The grid's detections for this camera and scene, from this process's cache when it has them.

    Args:
        camera: the endoscope.
        scene_key: everything in the scene the renders depend on besides the camera
            (hashable), or None: not cacheable, detect afresh.
        render_both: renders the left and the right full frame with the tool retracted;
            called only when the detections are not cached.

    Returns:
        35 detections in grid order. Their arrays are read-only: they may be shared by
        every world with the same key.
    """
    key = None if scene_key is None else (_camera_key(camera), scene_key)
    if key is not None:
        with _LOCK:
            cached = _CACHE.get(key)
            if cached is not None:
                _CACHE.move_to_end(key)
                return cached
    detections = tuple(_read_only(d) for d in detect_printed_grid(camera, *render_both()))
    if key is not None:
        with _LOCK:
            _CACHE[key] = detections
            while len(_CACHE) > CACHE_SIZE:
                _CACHE.popitem(last=False)
    return detections


def clear_cache() -> None:
    """Forget every scene's detections (the next observation of each renders again)."""
    with _LOCK:
        _CACHE.clear()


def _camera_key(camera: StereoCamera) -> tuple:
    """What of the camera decides the detections: the renders' image size, projection and
    both views, and the baseline the triangulation assumes."""
    k = camera.intrinsics
    views = (tuple(camera.view_matrix("left")), tuple(camera.view_matrix("right")))
    return (k.width, k.height, tuple(camera.projection_matrix()), views, camera.calibrated_baseline_m)


def _read_only(detection: StereoDetection) -> StereoDetection:
    for array in (detection.left_uv, detection.right_uv, detection.camera_position):
        array.setflags(write=False)
    return detection


def _blob_or_none(uv: np.ndarray) -> Blob | None:
    return None if not np.isfinite(uv).all() else Blob(uv, 0.0, False)
