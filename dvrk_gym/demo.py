"""The demo: touch grid circles with the uncalibrated robot and record what happens.

The robot aims its jaw tip at each circle with its own nominal kinematics, as an
uncalibrated dVRK would; the cable bias makes it miss. :func:`run_demo` records, per
circle, where the robot reported its tip, where the tip really was, the miss in
millimetres and in left-image pixels, and what the endoscope saw of the red marker, and
saves the stereo pair of the last touch as PNG (``dvrk-gym demo`` prints it all).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from dvrk_gym import paper
from dvrk_gym.sim.endoscope.stereo import StereoDetection
from dvrk_gym.sim.physics.scene import grid_circle_centers
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.world import DvrkWorld, WorldConfig
from dvrk_gym.utils.atomic import atomic_write_bytes

APPROACH_HEIGHT_M = 0.012
"""The tool first goes this far above a circle, then down to touch it."""


def tool_pose_for_tip(target: np.ndarray, yaw_rad: float) -> np.ndarray:
    """The nominal tool pose whose closed-jaw tip is at ``target`` (base frame, m).

    Pitch and roll follow from yaw by the paper's rule.
    """
    pitch, roll = kin.paper_pitch_roll(yaw_rad)
    pose = kin.pose_from_euler(np.zeros(3), yaw_rad, float(pitch), float(roll))
    pose[:3, 3] = np.asarray(target, dtype=float) - pose[:3, 2] * kin.JAW_LENGTH_M
    return pose


@dataclass(frozen=True)
class Touch:
    """One circle touched.

    Attributes:
        circle: the circle's index (row-major, 0-34).
        reported_tip_m: where the robot reported its jaw tip, (x, y, z) base frame, metres.
        true_tip_m: where the jaw tip really was, (x, y, z) base frame, metres.
        miss_mm: the true tip's distance from the circle's centre in the grid's plane, millimetres.
        miss_px: the same in the left image, pixels (NaN if the circle was not found there).
        marker: what the endoscope saw of the red marker.
    """

    circle: int
    reported_tip_m: np.ndarray
    true_tip_m: np.ndarray
    miss_mm: float
    miss_px: float
    marker: StereoDetection


@dataclass(frozen=True)
class DemoResult:
    """What the demo saw.

    Attributes:
        circles_found: grid circles the endoscope found in both images (of 35).
        touches: one per circle touched, in order.
        sim_time_s: simulated robot time of the whole demo, seconds.
        images: the PNG files written ("left", "right", "stereo").
    """

    circles_found: int
    touches: list[Touch]
    sim_time_s: float
    images: dict[str, Path]


def _touch(world: DvrkWorld, index: int, grid: Sequence[StereoDetection], rng: np.random.Generator) -> Touch:
    """Touch circle ``index`` from above, at the yaw its index picks, and record it."""
    yaw = float(kin.PAPER_YAWS_RAD[index % len(kin.PAPER_YAWS_RAD)])
    target = grid_circle_centers()[index]
    world.move_to(tool_pose_for_tip(target + [0, 0, APPROACH_HEIGHT_M], yaw), noise_rng=rng)
    world.move_to(tool_pose_for_tip(target, yaw), noise_rng=rng)
    true_tip = world.true_touch_point()
    tip_px = world.camera.project(true_tip)[0][0]
    miss_px = float(np.linalg.norm(tip_px - grid[index].left_uv)) if grid[index].seen_left else float("nan")
    touch = Touch(
        index, kin.touch_point(world.q_cmd), true_tip, float(1e3 * np.linalg.norm((true_tip - target)[:2])), miss_px, world.observe_marker()
    )
    world.move_to(tool_pose_for_tip(target + [0, 0, APPROACH_HEIGHT_M], yaw), noise_rng=rng)
    world.move_to(tool_pose_for_tip(target, yaw), noise_rng=rng)
    return touch


def _save_images(world: DvrkWorld, out: Path) -> dict[str, Path]:
    """Write the stereo pair as PNG (each file whole or not at all); OSError if one cannot be written."""
    left, right = world.render("left"), world.render("right")
    paths = {name: out / f"{name}.png" for name in ("left", "right", "stereo")}
    for name, image in (("left", left), ("right", right), ("stereo", np.hstack([left, right]))):
        encoded, png = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        if not encoded:
            raise OSError(f"OpenCV could not encode the {name} image ({image.shape}) as PNG")
        atomic_write_bytes(paths[name], png.tobytes())
    return paths


def run_demo(
    out: Path, *, bias: str = "paper", bias_seed: int = 0, resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX, n_circles: int = 7
) -> DemoResult:
    """Touch ``n_circles`` circles spread over the grid and write ``left.png``, ``right.png``
    and ``stereo.png`` (the last touch) into ``out``.

    Raises:
        ValueError: ``n_circles`` is not in 1..35.
    """
    if not 1 <= n_circles <= paper.GRID_CIRCLES:
        raise ValueError(f"n_circles (--circles) must be in 1..{paper.GRID_CIRCLES}, got {n_circles}")
    out.mkdir(parents=True, exist_ok=True)
    world = DvrkWorld(WorldConfig(camera_resolution=resolution, bias=bias, bias_seed=bias_seed))
    rng = np.random.default_rng(0)
    try:
        grid = world.observe_grid()
        order = np.linspace(0, paper.GRID_CIRCLES - 1, n_circles).round().astype(int)
        touches = [_touch(world, int(index), grid, rng) for index in order]
        images = _save_images(world, out)
        return DemoResult(sum(d.seen_both for d in grid), touches, world.clock.time_s, images)
    finally:
        world.close()
