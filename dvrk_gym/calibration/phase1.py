"""Phase I data collection: the paper's random exploration and its cleaning rule.

The paper ran 57 trajectories from the four workspace corners, pausing "about every
millimetre" to take three random rotations (yaw U[-90, 90], pitch U[-15, 25], roll
U[-180, -150] degrees), and kept the samples where both cameras saw the red marker at the
same place: 1,939 of 5,256 (37%); the rest the wrist hid, or the detector missed, or it
appeared outside the detector's search boxes. The authors' code
(:data:`dvrk_gym.paper.AUTHORS_CODE`) gives the details followed here: each trajectory runs
straight from a corner 5 mm over the paper towards a random target 1 mm over it, pausing
every 2 mm (as their real rows confirm: :data:`dvrk_gym.paper.PHASE1_STEP_M`); at each pause
it records the trajectory's own orientation first and then the three random ones, a new yaw
at most 150 degrees from the last; and "the same place" means that the right camera's
detection lies less than 12 px from where an affine map, fitted to the grid circles seen by
both cameras, sends the left one (:func:`clean_mask`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

from dvrk_gym import paper
from dvrk_gym.calibration.records import ArrayRecord, non_finite_rows
from dvrk_gym.envs.exploration import (
    PITCH_RANGE_RAD,
    ROLL_RANGE_RAD,
    SAFE_X_M,
    SAFE_Y_M,
    TARGET_Z_M,
    YAW_RANGE_RAD,
    CalibrationExplorationEnv,
    workspace_corners,
)
from dvrk_gym.sim.robot.bias import BiasConfig
from dvrk_gym.utils.checks import check_float, check_int

MAX_TRAJECTORIES = 10_000
MAX_STEPS_PER_TRAJECTORY = 10_000
"""Bounds of a run's Phase I (the paper: 57 trajectories of about 92 poses); here, not in the
pipeline, so that the CLI checks ``--trajectories`` without importing torch."""

MAX_YAW_STEP_RAD = float(np.deg2rad(150.0))
"""The authors' sampler redraws a yaw more than this from the previous one (no extreme flips), rad."""


class PaperExplorationPolicy:
    """The paper's Phase I protocol, as the authors' code ran it, as a policy from observation to action.

    Each trajectory draws its own orientation and a random target 1 mm over the paper
    (x and y uniform in the safe ranges, at :data:`~dvrk_gym.envs.exploration.TARGET_Z_M`),
    and heads for it from where the episode started (a corner 5 mm over the paper) in steps
    of ``step_m``. At every pause it commands the trajectory's orientation, then
    ``rotations_per_pause`` random ones, each yaw within 150 degrees of the one before. The
    last pause lies within ``step_m`` of the target; then, as the authors' collector began
    its next trajectory, it moves to a random corner with a new orientation and target (at
    the paper's 93 poses an episode, 23 pauses 2 mm apart, over a third of the episodes get
    that far: the corners lie 49 mm from a random target on average).

    Args:
        seed: seeds the policy's own generator (targets and rotations).
        step_m: distance between pauses, metres (the authors' collector: 2 mm).
        rotations_per_pause: random orientations commanded at each pause after the
            trajectory's own (the paper: 3).

    Raises:
        ValueError: ``step_m`` not in (0, 1] m, or ``rotations_per_pause`` not an int in [1, 1000].
    """

    def __init__(
        self, seed: int | None = None, step_m: float = paper.PHASE1_STEP_M, rotations_per_pause: int = paper.PHASE1_ROTATIONS_PER_PAUSE
    ) -> None:
        check_float("step_m", step_m, low=0.0, high=1.0, low_open=True, unit="m")  # not 0, not inf: the pauses must come
        check_int("rotations_per_pause", rotations_per_pause, 1, 1000)  # 2.7 was truncated to 2
        self.rng = np.random.default_rng(seed)
        self.step_m = float(step_m)
        self.rotations_per_pause = int(rotations_per_pause)
        self._position: np.ndarray | None = None
        self._target = np.zeros(3)
        self._home_rotation = np.zeros(3)
        self._last_yaw = 0.0
        self._poses_left = 0

    def reset(self, observation: dict[str, np.ndarray]) -> None:
        """Start a new trajectory from the reported position in ``observation``."""
        self._position = np.asarray(observation["reported_pose"][:3], dtype=float)
        self._home_rotation = self._draw_rotation(None)
        self._target = self._draw_target()
        self._poses_left = self.rotations_per_pause + 1

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """The next action (bx, by, bz, yaw, pitch, roll), base frame, metres and radians."""
        if self._position is None:
            self.reset(observation)
        if self._poses_left == 0:
            self._advance()
            self._poses_left = self.rotations_per_pause + 1
        first = self._poses_left == self.rotations_per_pause + 1
        self._poses_left -= 1
        rotation = self._home_rotation if first else self._draw_rotation(self._last_yaw)
        self._last_yaw = float(rotation[0])
        return np.concatenate([self._position, rotation]).astype(np.float32)

    def _draw_rotation(self, previous_yaw: float | None) -> np.ndarray:
        yaw = self.rng.uniform(*YAW_RANGE_RAD)
        while previous_yaw is not None and abs(yaw - previous_yaw) > MAX_YAW_STEP_RAD:
            yaw = self.rng.uniform(*YAW_RANGE_RAD)
        return np.array([yaw, self.rng.uniform(*PITCH_RANGE_RAD), self.rng.uniform(*ROLL_RANGE_RAD)])

    def _draw_target(self) -> np.ndarray:
        return np.array([self.rng.uniform(*SAFE_X_M), self.rng.uniform(*SAFE_Y_M), TARGET_Z_M])

    def _advance(self) -> None:
        if self._position is None:  # set by reset, which the first call makes
            raise RuntimeError("the policy advances from a position: call it with an observation first")
        offset = self._target - self._position
        distance = float(np.linalg.norm(offset))
        if distance <= self.step_m:  # the authors' next trajectory: from a corner, with its own orientation
            self._position = workspace_corners()[self.rng.integers(4)]
            self._home_rotation = self._draw_rotation(None)
            self._target = self._draw_target()
        else:
            self._position = self._position + offset * (self.step_m / distance)


@dataclass(frozen=True)
class Phase1Data(ArrayRecord):
    """Phase I samples, one row per commanded pose (SI units).

    Attributes:
        reported_position: (N, 3) the robot's reported base position, m.
        orientation: (N, 3) the reported (yaw, pitch, roll), rad (the command's, but for the
            wrist's settle lag, :attr:`dvrk_gym.sim.robot.bias.BiasConfig.wrist_settle_lag`).
        left_px: (N, 2) the marker in the left image, px (NaN when unseen).
        right_px: (N, 2) the marker in the right image, px (NaN when unseen).
        areas_px: (N, 2) the marker's blob area in the left and right images, px (0 unseen).
        camera_position: (N, 3) triangulated marker position, left camera frame, m (NaN
            unless both cameras saw it).
        trajectory: (N,) which episode each row came from (one of the protocol's
            trajectories, or more: :class:`PaperExplorationPolicy`).
        kept: (N,) whether the row passes the cleaning rule (:func:`clean_mask`).
    """

    reported_position: np.ndarray
    orientation: np.ndarray
    left_px: np.ndarray
    right_px: np.ndarray
    areas_px: np.ndarray
    camera_position: np.ndarray
    trajectory: np.ndarray
    kept: np.ndarray
    ROW_LAYOUT = {
        "reported_position": ((3,), "f"),
        "orientation": ((3,), "f"),
        "left_px": ((2,), "f"),
        "right_px": ((2,), "f"),
        "areas_px": ((2,), "f"),
        "camera_position": ((3,), "f"),
        "trajectory": ((), "iu"),
        "kept": ((), "b"),
    }

    @classmethod
    def value_problem(cls, data: dict[str, np.ndarray]) -> str | None:
        """No rows; a commanded or reported pose that is not finite; or a kept row without a
        finite camera position (what the calibrators fit on)."""
        if len(data["kept"]) == 0:
            return "it holds no rows"
        problems = (
            non_finite_rows("reported_position", data["reported_position"]),
            non_finite_rows("orientation", data["orientation"]),
            non_finite_rows("camera_position of a kept row", data["camera_position"][data["kept"]]),
        )
        return next((problem for problem in problems if problem is not None), None)

    @property
    def n_raw(self) -> int:
        return int(len(self.kept))

    @property
    def n_kept(self) -> int:
        return int(self.kept.sum())

    def cleaned(self) -> Phase1Data:
        """Only the kept rows."""
        return Phase1Data(**{f.name: getattr(self, f.name)[self.kept] for f in fields(self)})

    @property
    def X(self) -> np.ndarray:
        """Calibration inputs (N, 6): camera position (m) and yaw, pitch, roll (rad)."""
        return np.hstack([self.camera_position, self.orientation])

    @property
    def y(self) -> np.ndarray:
        """Calibration targets (N, 3): reported base position, m."""
        return self.reported_position


def left_to_right_map(left_px: np.ndarray, right_px: np.ndarray) -> np.ndarray:
    """The authors' affine map from left to right pixels, fitted to points seen by both cameras.

    Least squares over the points where both are finite (the grid circles: where a point
    of the paper's plane appears in the right image, given where it appears in the left).

    Args:
        left_px: (N, 2) left pixels (NaN where unseen).
        right_px: (N, 2) right pixels (NaN where unseen).

    Returns:
        (3, 2) matrix M with ``right ~= [u_left, v_left, 1] @ M``.

    Raises:
        ValueError: fewer than three points seen by both cameras.
    """
    both = np.isfinite(left_px).all(axis=1) & np.isfinite(right_px).all(axis=1)
    if both.sum() < 3:
        raise ValueError(f"an affine left-to-right map needs at least 3 points seen by both cameras, got {int(both.sum())}")
    design = np.hstack([left_px[both], np.ones((int(both.sum()), 1))])
    return np.linalg.lstsq(design, right_px[both], rcond=None)[0]


def clean_mask(left_px: np.ndarray, right_px: np.ndarray, left_to_right: np.ndarray, image_width: int) -> np.ndarray:
    """The authors' cleaning rule: both cameras saw the marker, at the same place.

    A row is kept when both detections exist and the right one lies less than
    :data:`dvrk_gym.paper.MARKER_GATE_PX` (12 px at 1920 wide, scaled to image_width) from
    where ``left_to_right`` (:func:`left_to_right_map` of the grid circles) sends the left
    one. The gate holds the row mismatch and the disparity's departure from the grid
    plane's together, so a row up to 11 px off is kept, as in the real data.

    Args:
        left_px: (N, 2) left detections, pixels (NaN when unseen).
        right_px: (N, 2) right detections, pixels (NaN when unseen).
        left_to_right: (3, 2) affine map, see :func:`left_to_right_map`.
        image_width: width of the images, pixels.
    """
    gate = paper.MARKER_GATE_PX * image_width / paper.ENDOSCOPE_RESOLUTION_PX[0]
    seen = np.isfinite(left_px).all(axis=1) & np.isfinite(right_px).all(axis=1)
    expected = np.hstack([np.nan_to_num(left_px), np.ones((len(left_px), 1))]) @ left_to_right
    distance = np.linalg.norm(np.nan_to_num(right_px) - expected, axis=1)
    return seen & (distance < gate)


def grid_left_to_right_map(env: gym.Env) -> np.ndarray:
    """:func:`left_to_right_map` of the grid circles as the env's endoscope sees them (pixels only)."""
    unwrapped: Any = env.unwrapped  # CalibrationExploration-v0
    grid = unwrapped.world.observe_grid()
    return left_to_right_map(np.array([d.left_uv for d in grid]), np.array([d.right_uv for d in grid]))


def _or_nan(value: np.ndarray | None, size: int) -> np.ndarray:
    return np.full(size, np.nan) if value is None else np.asarray(value, dtype=float)


def collect_phase1(
    env: gym.Env, policy: PaperExplorationPolicy, n_trajectories: int, seed: int = 0, *, progress: bool = True
) -> Phase1Data:
    """Run the paper's Phase I: ``n_trajectories`` episodes of CalibrationExploration-v0.

    Args:
        env: a CalibrationExploration-v0 environment (wrapped or not).
        policy: chooses the commanded poses.
        n_trajectories: how many trajectories (episodes) to run (the paper: 57).
        seed: episode ``k`` is reset with seed ``seed + k``.
        progress: show a progress bar.

    Returns:
        Every commanded pose as a raw row, with the cleaning rule's verdict in ``kept``.
    """
    check_int("n_trajectories", n_trajectories, 1, MAX_TRAJECTORIES)
    check_int("seed", seed, 0)  # episode k is reset with seed + k
    if not isinstance(env.unwrapped, CalibrationExplorationEnv):
        raise ValueError(f"Phase I runs on CalibrationExploration-v0, got {type(env.unwrapped).__name__}")
    width, height = env.unwrapped.config.camera_resolution
    try:  # before the collection: its cleaning rule matches the marker's pixels through the grid's
        left_to_right = grid_left_to_right_map(env)
    except ValueError as error:
        raise ValueError(
            f"at a camera_resolution of {width} x {height} px the endoscope does not see the printed grid ({error}); "
            "Phase I's cleaning rule needs it: give a larger resolution"
        ) from error
    rows: dict[str, list] = {
        name: [] for name in ("reported_position", "orientation", "left_px", "right_px", "areas_px", "camera_position", "trajectory")
    }
    for k in tqdm(range(n_trajectories), desc="Phase I trajectories", disable=not progress):
        observation, _ = env.reset(seed=seed + k)
        policy.reset(observation)
        done = False
        while not done:
            action = policy(observation)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            rows["reported_position"].append(info["reported_position"])
            rows["orientation"].append(info["reported_orientation"])
            rows["left_px"].append(_or_nan(info["marker_left_uv"], 2))
            rows["right_px"].append(_or_nan(info["marker_right_uv"], 2))
            rows["areas_px"].append(info["marker_areas_px"])
            rows["camera_position"].append(_or_nan(info["marker_camera_position"], 3))
            rows["trajectory"].append(k)
    arrays = {name: np.array(values) for name, values in rows.items()}
    kept = clean_mask(arrays["left_px"], arrays["right_px"], left_to_right, width)
    return Phase1Data(**arrays, kept=kept)


def run_paper_phase1(
    *,
    n_trajectories: int = paper.PHASE1_TRAJECTORIES,
    seed: int = 0,
    steps_per_trajectory: int = paper.PHASE1_POSES_PER_TRAJECTORY,
    bias: str | BiasConfig = "paper",
    bias_seed: int = 0,
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX,
    progress: bool = True,
) -> Phase1Data:
    """The paper's Phase I on a fresh CalibrationExploration-v0 (closed after).

    Args:
        n_trajectories: trajectories (episodes) to run (the paper: 57).
        seed: seeds the exploration policy and the episodes (:func:`collect_phase1`).
        steps_per_trajectory: commanded poses per trajectory.
        bias: the cable bias preset, or a configuration.
        bias_seed: which instrument.
        camera_resolution: the endoscope's image size (width, height), pixels.
        progress: show a progress bar.
    """
    check_int("n_trajectories", n_trajectories, 1, MAX_TRAJECTORIES)  # before an env is built
    world: dict[str, Any] = {"bias": bias, "bias_seed": bias_seed, "camera_resolution": tuple(camera_resolution)}
    env = gym.make("dvrk_gym/CalibrationExploration-v0", max_steps=steps_per_trajectory, **world)
    try:
        return collect_phase1(env, PaperExplorationPolicy(seed=seed), n_trajectories, seed=seed, progress=progress)
    finally:
        env.close()
