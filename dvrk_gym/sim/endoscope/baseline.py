"""The endoscope's stereo baseline: the one the authors' calibration gives and triangulates
with, and the true one the simulated endoscope renders with (metres)."""

from __future__ import annotations

import math

from dvrk_gym import paper
from dvrk_gym.sim import identified

__all__ = ["PAPER_BASELINE_M", "TRUE_BASELINE_M", "true_baseline_m"]

PAPER_BASELINE_M = paper.ENDOSCOPE_BASELINE_M
"""The baseline the authors' stereo calibration gives, and triangulates with, metres."""


def true_baseline_m(tape_right_shift_px: float) -> float:
    """The baseline the simulated endoscope renders with, metres, for a red-tape detector whose
    right-image centroid lies ``tape_right_shift_px`` px (at 1080p) left of the tape.

    The real rows put the tape ``depth_scale`` (0.95) times as far from the lens as it was
    (:data:`dvrk_gym.sim.identified.CAMERA`), and they cannot say how much of that is the
    stereo calibration (a baseline short of the true one: everything seen nearer) and how
    much the tape detector's right-image shift (the tape alone seen nearer). With the shift
    given, the true baseline B is the one that keeps the tape where the rows put it at
    their median depth Z (:data:`~dvrk_gym.sim.identified.TAPE_ROWS_DEPTH_M`): the authors
    triangulate f b / (f B / Z + shift) = depth_scale Z, with their baseline b. (Nearer or
    farther the tape is seen a little off depth_scale Z: +0.45 mm at 0.180 m, -0.33 mm at
    0.204 m, the rows' 5th and 95th percentiles.)

    Raises:
        ValueError: the shift is not finite, or so large that no positive baseline keeps
            the tape there.
    """
    if not math.isfinite(tape_right_shift_px):
        raise ValueError(f"tape_right_shift_px must be a finite number of pixels, got {tape_right_shift_px!r}")
    focal = paper.ENDOSCOPE_FOCAL_PX
    depth = identified.TAPE_ROWS_DEPTH_M
    baseline = PAPER_BASELINE_M / identified.CAMERA.depth_scale - tape_right_shift_px * depth / focal
    if baseline <= 0.0:
        raise ValueError(f"tape_right_shift_px = {tape_right_shift_px} px leaves no positive baseline ({baseline} m)")
    return baseline


TRUE_BASELINE_M = true_baseline_m(identified.TAPE_RIGHT_SHIFT_PX)
"""The baseline the simulated endoscope renders with, metres (:func:`true_baseline_m` of the
identified tape shift, :data:`dvrk_gym.sim.identified.TAPE_RIGHT_SHIFT_PX`)."""
