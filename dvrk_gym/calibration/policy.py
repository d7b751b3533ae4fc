"""CalibratedPolicy: camera-frame targets in, base-frame robot commands out.

A target policy chooses *what* to touch as the endoscope sees it (a camera-frame point and
an angle, e.g. a fragment's major axis); the calibrator says *where to send the robot* so
that it gets there. The yaw is rounded to the nearest of the paper's five yaws (the
calibrators were trained on them) and pitch and roll follow from it by the paper's rule.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from dvrk_gym.calibration.models.features import MAX_ANGLE_RAD, check_targets
from dvrk_gym.sim.robot import kinematics as kin

Target = tuple[np.ndarray, float]
"""A camera-frame point (x, y, z) in metres and an angle in radians."""


class Calibrator(Protocol):
    """Anything that maps (camera position m, yaw, pitch, roll rad) rows to base positions (m)."""

    def predict(self, X: np.ndarray) -> np.ndarray: ...


def grid_touch_target(observation: dict[str, np.ndarray]) -> Target:
    """GridTouch-v0's target: the circle as the endoscope sees it, with the episode's yaw.

    Raises:
        ValueError: the observation is not GridTouch-v0's (Debridement-v0's wants
            ``target=fragment_target``).
    """
    if not isinstance(observation, dict) or not {"desired_goal", "observation"} <= set(observation):
        keys = sorted(observation) if isinstance(observation, dict) else type(observation).__name__
        raise ValueError(
            f"the default target reads GridTouch-v0's observation ('desired_goal', 'observation'), got {keys}; "
            "give CalibratedPolicy a target for other envs (Debridement-v0: target=fragment_target)"
        )
    return np.asarray(observation["desired_goal"], dtype=float), float(observation["observation"][-1])


def calibrator_input(camera_position: np.ndarray, yaw_rad: float, round_yaw: bool = True) -> np.ndarray:
    """The (1, 6) calibrator input for a camera-frame point (m) and a yaw (rad; rounded to the
    nearest of the paper's five if asked).

    Raises:
        ValueError: the point is not three finite real numbers, or the yaw not a finite real
            number (a NaN yaw would otherwise round to -90 degrees, silently).
    """
    point = np.asarray(camera_position)
    if point.shape != (3,) or point.dtype.kind not in "fiu" or not np.isfinite(point).all():
        raise ValueError(f"the camera-frame target must be 3 finite real numbers (m), got {camera_position!r}")
    if (
        isinstance(yaw_rad, (bool, np.bool_))
        or not isinstance(yaw_rad, (int, float, np.integer, np.floating))
        or not abs(float(yaw_rad)) <= MAX_ANGLE_RAD  # NaN too; degrees (30) would round to a paper yaw silently
    ):
        raise ValueError(f"the target's yaw must be a finite real number of radians (within 2 pi), got {yaw_rad!r}")
    yaw = float(kin.nearest_paper_yaw(yaw_rad)) if round_yaw else float(yaw_rad)
    pitch, roll = kin.paper_pitch_roll(yaw)
    return np.array([[*point.astype(float), yaw, float(pitch), float(roll)]])


class CalibratedPolicy:
    """Turn camera-frame targets into the base-frame actions ``(bx, by, bz, yaw)``.

    Args:
        calibrator: a fitted calibrator with ``predict`` (RigidBodyCalibrator,
            DNNCalibrator, TwoPhaseCalibrator, or your own).
        target: maps an observation to a camera-frame target and an angle (default: the
            GridTouch goal and yaw).
        round_yaw: round the yaw to the nearest of the paper's five yaws.
    """

    def __init__(self, calibrator: Calibrator, *, target: Callable[[Any], Target] = grid_touch_target, round_yaw: bool = True) -> None:
        if not hasattr(calibrator, "predict"):
            raise TypeError(f"calibrator must have a predict(X) method, got {type(calibrator).__name__}")
        if not isinstance(round_yaw, (bool, np.bool_)):
            raise ValueError(f"round_yaw must be True or False, got {round_yaw!r}")
        self.calibrator = calibrator
        self.target = target
        self.round_yaw = round_yaw

    def __call__(self, observation: Any) -> np.ndarray:
        camera_position, angle = self.target(observation)
        X = calibrator_input(camera_position, angle, self.round_yaw)
        base = np.asarray(self.calibrator.predict(X), dtype=float).reshape(-1)
        if base.shape != (3,) or not np.isfinite(base).all():
            raise ValueError(f"the calibrator returned {base!r} for input {X.ravel().tolist()}; expected 3 finite numbers")
        # millimetres would be clamped into the workspace and scored as a miss of centimetres
        check_targets(base[None, :], 1, name=f"{type(self.calibrator).__name__}.predict(X)")
        return np.array([*base, X[0, 3]], dtype=np.float32)
