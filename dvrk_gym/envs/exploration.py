"""CalibrationExploration-v0: the paper's Phase I, random exploration with a red marker.

An episode is one trajectory of the paper's protocol, or more when the policy reaches its
target and begins the next from a corner, as the authors' collector went on
(:class:`dvrk_gym.calibration.phase1.PaperExplorationPolicy`). It starts at one of the four
workspace corners; each step
commands the next tool pose ``(bx, by, bz, yaw, pitch, roll)`` (base frame, metres and
radians, the dVRK's Euler convention) and observes what the robot reports and what the
endoscope sees of the red marker on the wrist.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from dvrk_gym import paper
from dvrk_gym.envs.base import DvrkEnv, config_arguments
from dvrk_gym.envs.configs import ExplorationConfig
from dvrk_gym.sim.endoscope.stereo import StereoDetection
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig

SAFE_X_M = paper.REAL_PHASE1_X_RANGE_M
SAFE_Y_M = paper.REAL_PHASE1_Y_RANGE_M
"""The paper's safe exploration ranges in the base frame, metres (its data span these)."""
SAFE_Z_M = (-0.153, -0.147)
"""Heights of the reported point that keep the 10 mm jaws 1-8 mm above the paper, metres."""
PAPER_REPORTED_Z_M = -0.1526
"""Where the identified instrument reports its jaws pushed onto the paper (the grid's middle,
yaw 0, GridTouch-v0's simulated person's push; instruments 1 to 3 within 0.5 mm of it), base
frame z in metres: the plane the authors' collector measured its heights from."""
CORNER_Z_M = PAPER_REPORTED_Z_M + paper.PHASE1_CORNER_HEIGHT_M
"""Height of the four corners where Phase I trajectories start, 5 mm over the paper, metres."""
TARGET_Z_M = PAPER_REPORTED_Z_M + paper.PHASE1_TARGET_HEIGHT_M
"""Height of the targets Phase I trajectories head for, 1 mm over the paper, metres."""
YAW_RANGE_RAD = kin.PAPER_YAW_RANGE_RAD
PITCH_RANGE_RAD = kin.PAPER_PITCH_RANGE_RAD
ROLL_RANGE_RAD = kin.PAPER_ROLL_RANGE_RAD

ACTION_NAMES = ("bx", "by", "bz", "yaw", "pitch", "roll")
ACTION_LOW = np.array([0.0, 0.0, -0.170, YAW_RANGE_RAD[0], PITCH_RANGE_RAD[0], ROLL_RANGE_RAD[0]])
ACTION_HIGH = np.array([0.080, 0.085, -0.130, YAW_RANGE_RAD[1], PITCH_RANGE_RAD[1], ROLL_RANGE_RAD[1]])

CAMERA_BOX_LOW_M = np.array([-0.2, -0.2, 0.0])
CAMERA_BOX_HIGH_M = np.array([0.2, 0.2, 0.5])
"""Bounds of triangulated camera-frame positions in observations, metres (clipped)."""


def workspace_corners() -> np.ndarray:
    """The four corners where Phase I trajectories start, (4, 3) base frame, metres (at :data:`CORNER_Z_M`)."""
    return np.array([[x, y, CORNER_Z_M] for y in SAFE_Y_M for x in SAFE_X_M])


def sample_paper_poses(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` reachable tool poses from the paper's exploration distribution (4x4, metres).

    Positions uniform in the safe ranges, orientations uniform in the paper's rotation
    ranges; draws the nominal robot cannot reach are skipped.
    """
    poses: list[np.ndarray] = []
    while len(poses) < n:
        position = np.array([rng.uniform(*SAFE_X_M), rng.uniform(*SAFE_Y_M), rng.uniform(*SAFE_Z_M)])
        angles = [rng.uniform(*YAW_RANGE_RAD), rng.uniform(*PITCH_RANGE_RAD), rng.uniform(*ROLL_RANGE_RAD)]
        pose = kin.pose_from_euler(position, *angles)
        try:
            ik.inverse_kinematics(pose)
        except ik.UnreachablePoseError:
            continue
        poses.append(pose)
    return poses


def home_orientation() -> tuple[float, float, float]:
    """(yaw, pitch, roll) in radians of the paper's rest orientation: yaw 0, the paper's rule."""
    pitch, roll = kin.paper_pitch_roll(0.0)
    return 0.0, float(pitch), float(roll)


def marker_observation_space(width: int, height: int) -> dict[str, spaces.Space]:
    """Observation entries for a stereo detection of the red marker."""
    pixel_high = np.array([width, height, width, height], dtype=np.float32)
    return {
        "marker_seen": spaces.MultiBinary(2),
        "marker_pixels": spaces.Box(-1.0, pixel_high, dtype=np.float32),
        "marker_camera_position": spaces.Box(CAMERA_BOX_LOW_M.astype(np.float32), CAMERA_BOX_HIGH_M.astype(np.float32), dtype=np.float32),
    }


def reported_observation_space() -> dict[str, spaces.Space]:
    """Observation entries for what the robot reports: its pose and jaw."""
    pose_low = np.array([-0.3, -0.3, -0.3, -np.pi, -np.pi, -np.pi], dtype=np.float32)
    return {
        "reported_pose": spaces.Box(pose_low, -pose_low, dtype=np.float32),
        "jaw_angle": spaces.Box(np.float32(kin.JAW_LOWER_RAD), np.float32(kin.JAW_UPPER_RAD), shape=(1,), dtype=np.float32),
    }


def encode_detection(detection: StereoDetection) -> dict[str, np.ndarray]:
    """A stereo detection as observation arrays: unseen pixels are -1, unseen positions 0."""
    pixels = np.concatenate([detection.left_uv, detection.right_uv])
    position = detection.camera_position if detection.seen_both else np.zeros(3)
    return {
        "marker_seen": np.array([detection.seen_left, detection.seen_right], dtype=np.int8),
        "marker_pixels": np.where(np.isfinite(pixels), pixels, -1.0).astype(np.float32),
        "marker_camera_position": np.clip(position, CAMERA_BOX_LOW_M, CAMERA_BOX_HIGH_M).astype(np.float32),
    }


def encode_reported(reported_pose: np.ndarray, jaw_angle_rad: float) -> dict[str, np.ndarray]:
    """The robot's reported pose as (bx, by, bz, yaw, pitch, roll) and its jaw angle."""
    yaw, pitch, roll = kin.euler_from_pose(reported_pose)
    pose = np.concatenate([reported_pose[:3, 3], [yaw, pitch, roll]])
    return {"reported_pose": pose.astype(np.float32), "jaw_angle": np.array([jaw_angle_rad], dtype=np.float32)}


class CalibrationExplorationEnv(DvrkEnv[ExplorationConfig]):
    """Phase I of the paper: command poses, observe the reported pose and the red marker.

    Observation (a Dict): ``reported_pose`` (bx, by, bz in m; yaw, pitch, roll in rad),
    ``jaw_angle`` (rad), ``marker_seen`` (left, right), ``marker_pixels`` (u, v left then
    right, px; -1 when unseen), ``marker_camera_position`` (x, y, z in the left camera
    frame, m; 0 unless both cameras saw the marker). Reward is always 0: this is data
    collection. ``info`` carries the truth for evaluation under ``true_*`` names.

    Reset options:
        ``"corner"``: which workspace corner (0-3) the trajectory starts at; default a
            random one.
        ``"relax"``: True (the default, seeded or not: each of the authors' trajectories is
            collected alike) starts with relaxed cables, as a fresh env does; False goes
            to the start through the cables, which keep their history from the trajectory
            before (hysteresis), as GridTouch-v0 and Debridement-v0 do by default.
    """

    config_class = ExplorationConfig
    action_names = ACTION_NAMES
    option_names = ("corner", "relax")

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        bias: str | BiasConfig = "paper",
        bias_seed: int = 0,
        max_steps: int = paper.PHASE1_POSES_PER_TRAJECTORY,
        camera_resolution: tuple[int, int] = (1920, 1080),
        pixel_noise_px: float = 0.0,
        render_resolution: tuple[int, int] | None = None,
        renderer: str = "auto",
    ) -> None:
        """CalibrationExploration-v0, set up by the fields of :class:`ExplorationConfig` (listed below)."""
        super().__init__(ExplorationConfig(**config_arguments(locals())), render_mode=render_mode)
        width, height = self.config.camera_resolution
        self.action_space = spaces.Box(ACTION_LOW.astype(np.float32), ACTION_HIGH.astype(np.float32), dtype=np.float32)
        self.observation_space = spaces.Dict({**reported_observation_space(), **marker_observation_space(width, height)})
        self._steps = 0

    def _check_options(self, options: dict[str, Any], seeded: bool) -> None:
        super()._check_options(options, seeded)
        corner = options.get("corner")
        if corner is not None and (
            isinstance(corner, (bool, np.bool_)) or not isinstance(corner, (int, np.integer)) or corner not in (0, 1, 2, 3)
        ):
            raise ValueError(f"option 'corner' must be an int 0, 1, 2 or 3, got {corner!r}")

    def _reset_episode(self, options: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        corner = options.get("corner")
        corner = int(self.np_random.integers(4)) if corner is None else int(corner)
        start = kin.pose_from_euler(workspace_corners()[corner], *home_orientation())
        self.world.reset_robot(ik.inverse_kinematics(start), relax=bool(options.get("relax", True)))  # checked by _check_options
        self._steps = 0
        observation = self._observe()
        return observation, self._info(np.zeros(6, dtype=bool), np.zeros(6, dtype=bool), corner=corner)

    def _step_episode(self, action: np.ndarray, clamped: np.ndarray):
        pose = kin.pose_from_euler(action[:3], *action[3:])
        move = self.world.move_to(pose, noise_rng=self.np_random, clamp_to_limits=True)
        self._steps += 1
        truncated = self._steps >= self.config.max_steps
        observation = self._observe()
        return observation, 0.0, False, truncated, self._info(clamped, move.joints_clamped)

    def _observe(self) -> dict[str, np.ndarray]:
        detection = self.world.observe_marker(noise_rng=self.np_random)
        self._last_detection = detection
        return {**encode_reported(self.world.reported_pose(), self.world.jaw_angle), **encode_detection(detection)}

    def _info(self, clamped: np.ndarray, joints_clamped: np.ndarray, **extra: Any) -> dict[str, Any]:
        detection = self._last_detection
        reported = self.world.reported_pose()
        return {
            "clamped": self._clamped_names(clamped, joints_clamped),
            "reported_position": reported[:3, 3].copy(),
            "reported_orientation": np.array(kin.euler_from_pose(reported)),
            # None, not NaN, when unseen: NaN != NaN would make equal episodes look different.
            "marker_left_uv": detection.left_uv if detection.seen_left else None,
            "marker_right_uv": detection.right_uv if detection.seen_right else None,
            "marker_camera_position": detection.camera_position if detection.seen_both else None,
            "marker_areas_px": np.array([detection.left_area_px, detection.right_area_px]),
            "sim_time_s": self.world.clock.time_s,
            "true_marker_position": self.world.true_marker_position(),
            "true_tip_position": self.world.true_touch_point(),
            # A Phase I sample counts when both cameras saw the marker (a row the authors could use).
            "is_success": detection.seen_both,
            **extra,
        }
