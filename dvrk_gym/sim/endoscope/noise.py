"""Pixel noise of the endoscope's detections: a Gaussian model for every detector, the red
tape detector's own error, its right image's bias and the boxes it searches
(:class:`DetectionNoise`) and its whole pixels (:func:`whole_pixels`).

A detection's noise is given as a standard deviation in pixels of the paper's 1920 x 1080
images (:data:`~dvrk_gym.paper.ENDOSCOPE_RESOLUTION_PX`), so one setting means the
same angular error at any rendering resolution: at width w it is that sd times
w / 1920 pixels. Each noisy (u, v) takes one draw of two independent normals,
``rng.normal(0.0, sigma_px, size=2)``; with zero noise or no generator nothing is drawn,
so turning the noise off leaves every other random stream untouched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper
from dvrk_gym.sim import identified
from dvrk_gym.utils.checks import check_int

__all__ = [
    "MAX_PIXEL_NOISE_PX",
    "MAX_RIGHT_SHIFT_PX",
    "PAPER_WIDTH_PX",
    "PixelNoise",
    "DetectionNoise",
    "IDENTIFIED_MARKER_NOISE",
    "whole_pixels",
]

PAPER_WIDTH_PX: int = paper.ENDOSCOPE_RESOLUTION_PX[0]
"""Width of the paper's images (1920 px), at which a pixel-noise setting is given."""
MAX_RIGHT_SHIFT_PX = 20.0
"""The largest right-image bias a detector may have (:attr:`DetectionNoise.right_shift_px`), px at 1080p."""
MAX_PIXEL_NOISE_PX = 50.0
"""The largest detection noise a world or an env accepts (standard deviation at 1920 x 1080), pixels."""


@dataclass(frozen=True)
class PixelNoise:
    """Gaussian noise on detected pixel positions, for a camera of a given width.

    Attributes:
        sigma_px_at_1080p: sd of the noise on each of u and v, in pixels of a 1920 x 1080
            image (>= 0; zero: no noise).
        width_px: Width of the images the detections are made in, pixels.
    """

    sigma_px_at_1080p: float
    width_px: int = PAPER_WIDTH_PX

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma_px_at_1080p) and self.sigma_px_at_1080p >= 0):
            raise ValueError(f"sigma_px_at_1080p = {self.sigma_px_at_1080p}; expected a finite value >= 0")
        check_int("PixelNoise.width_px", self.width_px, 1)

    @property
    def sigma_px(self) -> float:
        """sd of the noise on each of u and v, in pixels of this camera's images."""
        return self.sigma_px_at_1080p * self.width_px / PAPER_WIDTH_PX

    def apply(self, uv: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """uv with noise added: uv + rng.normal(0.0, sigma_px, size=2).

        Args:
            uv: One detected (u, v), shape (2,) or (1, 2), pixels of this camera's images.
            rng: Source of the draw; None for exact detections.

        Returns:
            The noisy (u, v), pixels, shaped as uv; uv itself (nothing drawn) when rng is
            None or the noise is zero.
        """
        sigma_px = self.sigma_px
        if rng is None or sigma_px == 0.0:
            return uv
        return uv + rng.normal(0.0, sigma_px, size=2)

    def apply_floats(self, u: float, v: float, rng: np.random.Generator | None) -> tuple[float, float]:
        """:meth:`apply` to one pixel (``u``, ``v``) in Python floats: the same draw, the same numbers."""
        sigma_px = self.sigma_px
        if rng is None or sigma_px == 0.0:
            return u, v
        du, dv = rng.normal(0.0, sigma_px, size=2).tolist()
        return u + du, v + dv


@dataclass(frozen=True)
class DetectionNoise:
    """Error of one camera's centroid of a detected blob: a Gaussian core and rare outliers.

    Each camera's detection of the red tape errs by its own draw; a rectified pair's rows
    then differ by the difference of two draws, and so does its disparity (depth noise
    follows from it). A real detector errs so: the thresholded tape's outline flickers by a
    pixel or so, and now and then a specular highlight or the jaw's shadow cuts a piece off
    one camera's blob and moves its centroid several pixels. Values in pixels of a 1920 x
    1080 image; the identified ones, and how, are in
    :mod:`dvrk_gym.sim.identified`.

    Attributes:
        core_px: sd of the usual error on each of u and v, px at 1080p (>= 0).
        outlier_px: sd of the error of an outlying detection on each of u and v, px at 1080p (>= 0).
        outlier_probability: chance that a detection is an outlier, in [0, 1].
        miss_probability: chance that the detector finds no tape in an image where it is
            in view, in [0, 1].
        right_shift_px: how far left of the point's projection the right camera's centroid
            lies, px at 1080p, in [-MAX_RIGHT_SHIFT_PX, MAX_RIGHT_SHIFT_PX]: a bias, not
            noise (nothing is drawn for it). It widens every disparity by that much, so the
            thing is triangulated nearer than it is (positive) or farther (negative).
        search_boxes_px: the regions (u, v, width, height) of the left and the right image
            the detector searches, px at 1080p: a detection whose whole-pixel centroid does
            not lie strictly inside its image's box is no detection (None: the whole image).
            Like the misses, the boxes act on the noisy path only; exact detections (no
            generator) see the whole image.
    """

    core_px: float
    outlier_px: float
    outlier_probability: float
    miss_probability: float = 0.0
    right_shift_px: float = 0.0
    search_boxes_px: tuple[tuple[float, float, float, float], tuple[float, float, float, float]] | None = None

    def __post_init__(self) -> None:
        for name in ("core_px", "outlier_px"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"DetectionNoise.{name} = {value}; expected a finite value >= 0 px")
        for name in ("outlier_probability", "miss_probability"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"DetectionNoise.{name} = {value}; expected a value in [0, 1]")
        if not (math.isfinite(self.right_shift_px) and abs(self.right_shift_px) <= MAX_RIGHT_SHIFT_PX):
            raise ValueError(
                f"DetectionNoise.right_shift_px = {self.right_shift_px}; expected a finite value in "
                f"[-{MAX_RIGHT_SHIFT_PX:g}, {MAX_RIGHT_SHIFT_PX:g}] px"
            )
        if self.search_boxes_px is not None:
            boxes = np.asarray(self.search_boxes_px, dtype=float) if _box_shaped(self.search_boxes_px) else None
            if boxes is None or not np.all(np.isfinite(boxes)) or np.any(boxes[:, 2:] <= 0):
                raise ValueError(
                    f"DetectionNoise.search_boxes_px = {self.search_boxes_px!r}; expected two boxes (u, v, width, height) "
                    "of finite pixels with positive sizes, or None"
                )
            left, right = (tuple(float(x) for x in box) for box in boxes)
            object.__setattr__(self, "search_boxes_px", (left, right))  # frozen: stored as tuples of floats

    def searches(self, side: str, uv: np.ndarray, width_px: int = PAPER_WIDTH_PX) -> bool:
        """Whether a detection at ``uv`` (pixels of the ``side`` image, ``width_px`` wide) lies
        strictly inside that image's search box, measured in pixels of the paper's 1920 x 1080
        grid (always, without boxes)."""
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        if self.search_boxes_px is None:
            return True
        u0, v0, width, height = self.search_boxes_px[0 if side == "left" else 1]
        u, v = (np.asarray(uv, dtype=float).reshape(2) + 0.5) * (PAPER_WIDTH_PX / width_px) - 0.5
        # Strictly inside, with the rounding of a whole pixel brought back to 1080p allowed for.
        tolerance = 1e-6
        return bool(u0 + tolerance < u < u0 + width - tolerance and v0 + tolerance < v < v0 + height - tolerance)

    def shift(self, side: str, width_px: int = PAPER_WIDTH_PX) -> np.ndarray:
        """The bias (du, dv) of a centroid in the ``side`` ("left" or "right") image, pixels of an
        image ``width_px`` wide: (-right_shift_px, 0) scaled to that width in the right image,
        zero in the left."""
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        du = -self.right_shift_px * width_px / PAPER_WIDTH_PX if side == "right" else 0.0
        return np.array([du, 0.0])

    def misses(self, rng: np.random.Generator) -> bool:
        """Whether the detector misses the tape in one image: one uniform draw (none when miss_probability is 0)."""
        return self.miss_probability > 0.0 and bool(rng.uniform() < self.miss_probability)

    def sample(self, rng: np.random.Generator, width_px: int = PAPER_WIDTH_PX) -> np.ndarray:
        """One detection's error (du, dv), pixels of an image width_px wide.

        Draws, in this order: one uniform (outlier or not), then two normals.
        """
        outlier = rng.uniform() < self.outlier_probability
        sigma = self.outlier_px if outlier else self.core_px
        return rng.normal(0.0, sigma, size=2) * (width_px / PAPER_WIDTH_PX)

    def sample_many(self, rng: np.random.Generator, shape: tuple[int, ...], width_px: int = PAPER_WIDTH_PX) -> np.ndarray:
        """Errors (du, dv) of many detections at once, (*shape, 2) pixels of an image width_px wide.

        Each is distributed as one :meth:`sample` (the same mixture), but drawn in batches:
        all the uniforms (outlier or not), then all the normals; so not the same numbers as
        that many calls of :meth:`sample`.
        """
        outlier = rng.uniform(size=shape) < self.outlier_probability
        sigma = np.where(outlier, self.outlier_px, self.core_px)
        return rng.normal(size=(*shape, 2)) * sigma[..., None] * (width_px / PAPER_WIDTH_PX)


def _box_shaped(value: object) -> bool:
    """Whether ``value`` is two sequences of four real numbers (not booleans)."""
    return (
        isinstance(value, (tuple, list, np.ndarray))
        and len(value) == 2
        and all(
            isinstance(box, (tuple, list, np.ndarray))
            and len(box) == 4
            and all(isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_)) for x in box)
            for box in value
        )
    )


IDENTIFIED_MARKER_NOISE = DetectionNoise(
    core_px=identified.MARKER_DETECTION_NOISE.core_px,
    outlier_px=identified.MARKER_DETECTION_NOISE.outlier_px,
    outlier_probability=identified.MARKER_DETECTION_NOISE.outlier_probability,
    miss_probability=identified.MARKER_DETECTION_NOISE.miss_probability,
    right_shift_px=identified.TAPE_RIGHT_SHIFT_PX,
    search_boxes_px=paper.MARKER_SEARCH_BOXES_PX,
)
"""The red-tape detector's error identified from the real rows (:data:`dvrk_gym.sim.identified.MARKER_DETECTION_NOISE`),
searching the authors' boxes of each image (:data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`)."""


def whole_pixels(uv: np.ndarray, width_px: int) -> np.ndarray:
    """uv truncated to whole pixels of the paper's 1920 x 1080 grid, as the authors' detector did.

    Their detector took ``int()`` of the contour's centroid: the floor, for the positive
    coordinates of an image. At another width the same 1080p grid is used, so depth steps
    as the real camera's do at any rendering resolution.

    Args:
        uv: (..., 2) pixel coordinates of an image width_px wide (OpenCV convention, pixel
            centres at integers).
        width_px: the image's width, pixels.
    """
    scale = PAPER_WIDTH_PX / check_int("width_px", width_px, 1)
    paper_uv = (np.asarray(uv, dtype=float) + 0.5) * scale - 0.5
    return (np.floor(paper_uv) + 0.5) / scale - 0.5
