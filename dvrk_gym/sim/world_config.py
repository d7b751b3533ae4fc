"""How to build a world (:class:`WorldConfig`), what one commanded move did (:class:`MoveResult`),
and what drives the tool once something can be held (:class:`JawDriver`); the checks of
what a world is commanded (:func:`check_joints`, :func:`check_jaw_angle`, and the float
paths' cheaper :func:`finite_joint_floats`).

:mod:`dvrk_gym.sim.world`, which builds and runs the world, imports them all from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Protocol

import numpy as np

from dvrk_gym.sim.endoscope.camera import PAPER_INTRINSICS
from dvrk_gym.sim.endoscope.noise import IDENTIFIED_MARKER_NOISE, MAX_PIXEL_NOISE_PX, DetectionNoise
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig
from dvrk_gym.sim.robot.motion_limits import MotionLimits
from dvrk_gym.utils.checks import check_bool, check_endoscope_resolution, check_float, check_float_fields, check_int_fields

__all__ = ["JawDriver", "MoveResult", "WorldConfig", "check_jaw_angle", "check_joints", "finite_joint_floats"]


def check_jaw_angle(value: float) -> float:
    """A jaw opening as a float, rad, if it is finite and in [``JAW_LOWER_RAD``, ``JAW_UPPER_RAD``].

    Raises:
        ValueError: naming ``jaw_angle_rad`` and the range.
    """
    return check_float("jaw_angle_rad", value, low=kin.JAW_LOWER_RAD, high=kin.JAW_UPPER_RAD, unit="rad")


def check_joints(q: np.ndarray) -> np.ndarray:
    """Joints (6,) rad / m as a float array, if finite and within the joint limits.

    Raises:
        ValueError: not (6,) finite numbers.
        ik.UnreachablePoseError: outside the limits.
    """
    q = kin.finite_vector(q, 6, "q")
    if kin.joint_limit_violations(q, kin.JOINT_LIMIT_TOLERANCE):  # within_joint_limits would check q's values again
        raise ik.UnreachablePoseError(f"joints {np.round(q, 4).tolist()} are outside the joint limits")
    return q


def finite_joint_floats(q: list[float]) -> np.ndarray:
    """Joints (6,) rad / m as a float array, if all six are finite (the float paths' cheap check;
    the limits are not checked).

    Raises:
        ValueError: not six finite numbers.
    """
    if len(q) != 6 or not all(math.isfinite(value) for value in q):
        raise ValueError(f"q must be 6 finite joint values (rad / m), got {list(q)!r}")
    return np.array(q, dtype=float)


@dataclass(frozen=True)
class WorldConfig:
    """How to build a world.

    Attributes:
        camera_resolution: (width, height) of each endoscope image in pixels, of the paper's
            16:9 aspect to a pixel (the detector's noise, search boxes and whole pixels scale
            with the width); the paper's intrinsics are scaled to it.
        bias: the cable bias, a preset name ("none", "paper", "severe") or a BiasConfig.
        bias_seed: which instrument to draw from the bias distribution.
        gui: open the PyBullet GUI (needs a display).
        motion: the tool's speed and acceleration limits.
        camera_pose: T_base_leftcam (4x4, metres); None for the paper's set-up. Hidden
            from agents: they only see pixels.
        pixel_noise_px: standard deviation of the noise added to every detected pixel
            coordinate, at 1920 x 1080 (scaled with the resolution), on top of
            ``marker_noise`` for the red marker.
        marker_noise: the red-tape detector's own error in each camera, its right-image
            shift and the boxes it searches (the identified ones by default:
            :data:`dvrk_gym.sim.identified.MARKER_DETECTION_NOISE`,
            :data:`~dvrk_gym.sim.identified.TAPE_RIGHT_SHIFT_PX`, and the authors' boxes,
            :data:`dvrk_gym.paper.MARKER_SEARCH_BOXES_PX`). The shift also sets the
            baseline the endoscope renders with
            (:func:`dvrk_gym.sim.endoscope.baseline.true_baseline_m`), when the world is made,
            so that the tape is seen where the real rows put it.
    """

    camera_resolution: tuple[int, int] = (PAPER_INTRINSICS.width, PAPER_INTRINSICS.height)
    bias: str | BiasConfig = "paper"
    bias_seed: int = 0
    gui: bool = False
    motion: MotionLimits = field(default_factory=MotionLimits)
    camera_pose: np.ndarray | None = None
    pixel_noise_px: float = 0.0
    marker_noise: DetectionNoise = IDENTIFIED_MARKER_NOISE

    def __post_init__(self) -> None:
        check_float_fields("WorldConfig", self, {"pixel_noise_px": (0.0, MAX_PIXEL_NOISE_PX, False)})
        object.__setattr__(self, "camera_resolution", check_endoscope_resolution("camera_resolution", self.camera_resolution))
        check_int_fields("WorldConfig", self, {"bias_seed": (0, 2**31 - 1)})
        if not isinstance(self.bias, (str, BiasConfig)):
            raise ValueError(f"bias must be a preset name or a BiasConfig, got {self.bias!r}")
        check_bool("gui", self.gui)
        if not isinstance(self.motion, MotionLimits):
            raise ValueError(f"motion must be a MotionLimits, got {self.motion!r}")
        if not isinstance(self.marker_noise, DetectionNoise):
            raise ValueError(f"marker_noise must be a DetectionNoise, got {self.marker_noise!r}")
        if self.camera_pose is not None:
            pose = np.array(self.camera_pose)  # a copy: the caller's array may change after this check
            if pose.shape != (4, 4) or pose.dtype.kind != "f" or not np.all(np.isfinite(pose)):
                raise ValueError(f"camera_pose must be None or a finite 4x4 float transform (metres), got {self.camera_pose!r}")
            pose.flags.writeable = False
            object.__setattr__(self, "camera_pose", pose)

    def __eq__(self, other: object) -> bool:
        """Field by field, ``camera_pose`` by value (an array's ``==`` is elementwise, so the
        generated method raised for two configs with one)."""
        return self._key() == other._key() if isinstance(other, WorldConfig) else NotImplemented

    def __hash__(self) -> int:
        return hash(self._key())

    def _key(self) -> tuple[Any, ...]:
        pose = None if self.camera_pose is None else tuple(self.camera_pose.ravel().tolist())
        return tuple(pose if f.name == "camera_pose" else getattr(self, f.name) for f in fields(self))


@dataclass(frozen=True)
class MoveResult:
    """What one commanded move did.

    Attributes:
        duration_s: simulated seconds the move took (including settling).
        q_cmd: the commanded (and reported) joints after the move.
        q_true: the joints the cables actually produced.
        joints_clamped: which joints had to be clamped into their limits (bool, (6,)).
    """

    duration_s: float
    q_cmd: np.ndarray
    q_true: np.ndarray
    joints_clamped: np.ndarray


class JawDriver(Protocol):
    """Drives the tool body through the physics once something on the paper can be held.

    A world without one (``DvrkWorld.jaw_driver is None``) sets the tool body's joints
    itself; once a table (:class:`dvrk_gym.sim.table.table.DebridementTable`) installs
    one, the world calls it there instead, so what the jaws hold goes along with
    free-space moves and is let go of at a reset.
    """

    def place_tool(self, q_true: np.ndarray, jaw_angle_rad: float | None) -> float:
        """Teleport the tool to the true joints ``q_true`` (rad / m) without stepping physics,
        what it holds going along, and command the jaws to ``jaw_angle_rad`` (None: as
        they are); returns the jaws' opening now, rad."""

    def reset_tool(self, q_true: np.ndarray, jaw_angle_rad: float) -> None:
        """Let go of everything and put the tool at ``q_true`` with the jaws at ``jaw_angle_rad``."""

    def detach(self) -> None:
        """Let go of everything: the world is about to empty its physics server."""
