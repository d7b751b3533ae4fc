"""Pixel noise of the endoscope's detections: one Gaussian model for every detector.

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

__all__ = ["MAX_PIXEL_NOISE_PX", "PAPER_WIDTH_PX", "PixelNoise"]

PAPER_WIDTH_PX: int = paper.ENDOSCOPE_RESOLUTION_PX[0]
"""Width of the paper's images (1920 px), at which a pixel-noise setting is given."""
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
        if self.width_px <= 0:
            raise ValueError(f"width_px = {self.width_px}; expected a positive image width in pixels")

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
