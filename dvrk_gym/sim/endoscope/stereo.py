"""Stereo detections: one thing as the left and right endoscope images saw it, and where that puts it.

A :class:`StereoDetection` joins a left and a right detection (pixels) and, when both
cameras saw the thing with a positive disparity, its triangulated position in the left
camera's frame (metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.sim.endoscope.detection import Blob


@dataclass(frozen=True)
class StereoDetection:
    """A thing seen (or not) by both cameras.

    Attributes:
        left_uv: (u, v) in the left image, pixels; NaN when not seen.
        right_uv: (u, v) in the right image, pixels; NaN when not seen.
        camera_position: triangulated (x, y, z) in the left camera frame, metres; NaN
            unless both cameras saw it with a positive disparity.
        left_area_px: the detected region's area in the left image, pixels (0 when unseen).
        right_area_px: the same in the right image.
    """

    left_uv: np.ndarray
    right_uv: np.ndarray
    camera_position: np.ndarray
    left_area_px: float = 0.0
    right_area_px: float = 0.0

    @property
    def seen_left(self) -> bool:
        return bool(np.isfinite(self.left_uv).all())

    @property
    def seen_right(self) -> bool:
        return bool(np.isfinite(self.right_uv).all())

    @property
    def seen_both(self) -> bool:
        return bool(np.isfinite(self.camera_position).all())


def stereo_detection(camera: StereoCamera, left: Blob | None, right: Blob | None) -> StereoDetection:
    """Join a left and a right detection (None: not seen) into a :class:`StereoDetection`.

    The position is triangulated only when both were seen with a positive disparity
    (u_left - u_right > 0, pixels); otherwise it is NaN.
    """
    nan2 = np.full(2, np.nan)
    left_uv = nan2 if left is None else left.centroid
    right_uv = nan2 if right is None else right.centroid
    position = np.full(3, np.nan)
    if left is not None and right is not None and left_uv[0] - right_uv[0] > 0:
        position = camera.triangulate(left_uv, right_uv)[0]
    areas = [0.0 if blob is None else blob.area_px for blob in (left, right)]
    return StereoDetection(left_uv.copy(), right_uv.copy(), position, *areas)
