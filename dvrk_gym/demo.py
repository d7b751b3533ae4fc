"""``dvrk-gym demo``: touch grid circles with the uncalibrated robot and show what happens.

The robot aims its jaw tip at each circle with its own nominal kinematics, as an
uncalibrated dVRK would; the cable bias makes it miss. The demo prints, per circle, the
miss in millimetres and in left-image pixels, and what the endoscope saw of the red
marker, and saves the stereo pair of the last touch as PNG.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.world import DvrkWorld, WorldConfig
from dvrk_gym.sim.physics.scene import grid_circle_centers

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


def run_demo(out: Path, bias: str = "paper", bias_seed: int = 0, resolution: tuple[int, int] = (1920, 1080), n_circles: int = 7) -> int:
    """Run the demo and write ``left.png``, ``right.png`` and ``stereo.png`` into ``out``."""
    if not 1 <= n_circles <= 35:
        raise ValueError(f"--circles must be in 1..35, got {n_circles}")
    out.mkdir(parents=True, exist_ok=True)
    world = DvrkWorld(WorldConfig(camera_resolution=resolution, bias=bias, bias_seed=bias_seed))
    rng = np.random.default_rng(0)
    try:
        circles = grid_circle_centers()
        grid = world.observe_grid()
        found = sum(d.seen_both for d in grid)
        print(f"endoscope {resolution[0]}x{resolution[1]}: {found} of 35 grid circles found in both images")
        print(f"{'circle':>6} {'reported tip (mm)':>24} {'true tip (mm)':>24} {'miss mm':>8} {'miss px':>8}  marker seen (L/R)  marker camera xyz (mm)")
        order = np.linspace(0, 34, n_circles).round().astype(int)
        for index in order:
            yaw = float(kin.PAPER_YAWS_RAD[index % 5])
            target = circles[index]
            world.move_to(tool_pose_for_tip(target + [0, 0, APPROACH_HEIGHT_M], yaw), noise_rng=rng)
            world.move_to(tool_pose_for_tip(target, yaw), noise_rng=rng)
            reported = kin.touch_point(world.q_cmd)
            true_tip = world.true_touch_point()
            miss_mm = 1e3 * np.linalg.norm((true_tip - target)[:2])
            tip_px = world.camera.project(true_tip)[0][0]
            circle_px = grid[index].left_uv
            miss_px = float(np.linalg.norm(tip_px - circle_px)) if grid[index].seen_left else float("nan")
            marker = world.observe_marker()
            seen = f"{'yes' if marker.seen_left else 'no':>3}/{'yes' if marker.seen_right else 'no':<3}"
            xyz = "-" if not marker.seen_both else np.array2string(1e3 * marker.camera_position, precision=1)
            print(
                f"{index:>6} {np.array2string(1e3 * reported, precision=1):>24} "
                f"{np.array2string(1e3 * true_tip, precision=1):>24} {miss_mm:>8.2f} {miss_px:>8.1f}  {seen:>17}  {xyz}"
            )
            world.move_to(tool_pose_for_tip(target + [0, 0, APPROACH_HEIGHT_M], yaw), noise_rng=rng)
            world.move_to(tool_pose_for_tip(target, yaw), noise_rng=rng)
        left, right = world.render("left"), world.render("right")
        paths = {name: out / f"{name}.png" for name in ("left", "right", "stereo")}
        cv2.imwrite(str(paths["left"]), cv2.cvtColor(left, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(paths["right"]), cv2.cvtColor(right, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(paths["stereo"]), cv2.cvtColor(np.hstack([left, right]), cv2.COLOR_RGB2BGR))
        print(f"simulated robot time: {world.clock.time_s:.1f} s; images: {', '.join(str(p) for p in paths.values())}")
    finally:
        world.close()
    return 0
