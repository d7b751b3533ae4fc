"""Images for people to watch: the endoscope's view at any size, by the fastest renderer here.

Perception never comes through here: the detections render with TinyRenderer in the
world's own client (:meth:`StereoCamera.render`), bit for bit as before. What is drawn
here (``env.render()``, videos) may use PyBullet's EGL renderer in a mirror client of its
own (:class:`dvrk_gym.sim.physics.mirror.EglMirror`), 3.1-4.6x less CPU a frame, and may be
smaller than the detection image: its camera is the endoscope's, resampled.

``renderer``: "auto" uses EGL when it runs here and falls back to TinyRenderer (with one
log line saying why) when it does not; "egl" insists on it (an error if it cannot run);
"tiny" always uses TinyRenderer.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from dvrk_gym.sim.endoscope.camera import PixelWindow, StereoCamera
from dvrk_gym.sim.endoscope.renderers import DISPLAY_RENDERERS
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.physics.mirror import EGL_MAX_IMAGE_PX, EglMirror, RendererUnavailable, egl_forked, refuse_if_forked

logger = logging.getLogger(__name__)

EGL_NEAR_M = 0.03
"""The EGL renderer's near clipping plane, metres. At the camera's own (0.01 m) the printed
circles, 0.05 mm above the paper, showed through it in stripes (measured): the plugin asks
for a depth buffer of 8 bits or more, and 16 bits at 0.01 m resolve only 0.05 mm at the
paper; at 0.03 m, 0.02 mm. Nothing in view comes nearer than about 0.06 m (the shaft leaves
the frame before it reaches the remote centre, 0.11 m from the camera)."""
EGL_FAR_M = 0.5
"""The EGL renderer's far clipping plane, metres (nothing in view lies beyond 0.3 m)."""


class EndoscopeDisplay:
    """The endoscope's view for display, at ``resolution``, drawn by ``renderer``.

    Args:
        camera: the endoscope (its pose, baseline and intrinsics).
        resolution: (width, height) of the images, pixels; None: the camera's own. The
            intrinsics are the camera's, scaled.
        renderer: "auto", "egl" or "tiny" (module doc).
        plugin_path: the EGL plugin to use (default: pybullet's own).

    The renderer is chosen at the first image, so a display that never draws costs nothing.
    """

    def __init__(
        self,
        camera: StereoCamera,
        resolution: tuple[int, int] | None = None,
        renderer: str = "auto",
        plugin_path: str | None = None,
    ) -> None:
        if renderer not in DISPLAY_RENDERERS:
            raise ValueError(f"renderer must be one of {list(DISPLAY_RENDERERS)}, got {renderer!r}")
        k = camera.intrinsics
        width, height = (k.width, k.height) if resolution is None else resolution
        self.camera = StereoCamera(
            intrinsics=k.scaled(width, height),
            baseline_m=camera.baseline_m,
            pose=camera.pose,
            calibrated_baseline_m=camera.calibrated_baseline_m,
            near_m=camera.near_m,
            far_m=camera.far_m,
        )
        """The camera images are drawn for (the endoscope's, at this display's resolution)."""
        self._egl_camera = StereoCamera(
            intrinsics=self.camera.intrinsics,
            baseline_m=camera.baseline_m,
            pose=camera.pose,
            calibrated_baseline_m=camera.calibrated_baseline_m,
            near_m=EGL_NEAR_M,
            far_m=EGL_FAR_M,
        )
        self.requested = renderer
        self._plugin_path = plugin_path
        self._mirror: EglMirror | None = None
        self._chosen: str | None = None

    @property
    def renderer(self) -> str:
        """What draws the images: "egl" or "tiny" (choosing it now if no image was drawn yet)."""
        if self._chosen is None:
            self._chosen = self._choose()
        return self._chosen

    def _choose(self) -> str:
        if self.requested == "tiny":
            return "tiny"
        try:
            self._mirror = EglMirror(self._plugin_path)
        except RendererUnavailable as reason:
            if self.requested == "egl":
                raise RendererUnavailable(f"renderer='egl' was asked for, but {reason}; use renderer='auto' or 'tiny'") from None
            logger.warning("rendering with TinyRenderer (several times slower than EGL): %s", reason)
            return "tiny"
        return "egl"

    def image(self, physics: Physics, side: str = "left") -> np.ndarray:
        """What ``side`` ("left" or "right") of the endoscope sees in ``physics`` now: (h, w, 3) uint8 RGB."""
        if self.renderer == "egl" and egl_forked():  # a display drawing with EGL before this process was forked
            if self.requested == "egl":
                refuse_if_forked()
            logger.warning("rendering with TinyRenderer from now on: this process was forked after EGL started")
            self._mirror, self._chosen = None, "tiny"  # the mirror is the parent's: dropped, not closed
        if self.renderer == "tiny":
            return self.camera.render(physics.client, side)
        mirror = self._mirror
        if mirror is None:  # cannot happen: choosing "egl" made one, and close() forgets the choice
            raise RendererUnavailable("the display chose EGL but holds no mirror")
        mirror.sync(physics)
        camera = self._egl_camera
        k = camera.intrinsics
        view = camera.view_matrix(side)
        image = np.empty((k.height, k.width, 3), dtype=np.uint8)
        for tile in tiles(k.width, k.height, EGL_MAX_IMAGE_PX):
            projection = camera.projection_matrix(tile, renderer="opengl")
            image[tile.v0 : tile.v0 + tile.height, tile.u0 : tile.u0 + tile.width] = mirror.image(tile.width, tile.height, view, projection)
        return image

    def close(self) -> None:
        """Free the EGL mirror, if any; safe to call more than once."""
        if self._mirror is not None:
            self._mirror.close()
            self._mirror = None
        if self._chosen == "egl":
            self._chosen = None  # a later image makes a new mirror


def tiles(width: int, height: int, largest: tuple[int, int]) -> list[PixelWindow]:
    """Split a ``width`` x ``height`` image into the fewest equal-as-possible windows no larger
    than ``largest`` (width, height), pixels; row-major."""
    columns, rows = math.ceil(width / largest[0]), math.ceil(height / largest[1])
    u_edges = [round(i * width / columns) for i in range(columns + 1)]
    v_edges = [round(j * height / rows) for j in range(rows + 1)]
    return [
        PixelWindow(u_edges[i], v_edges[j], u_edges[i + 1] - u_edges[i], v_edges[j + 1] - v_edges[j])
        for j in range(rows)
        for i in range(columns)
    ]
