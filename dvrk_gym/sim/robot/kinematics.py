"""Forward kinematics of the dVRK PSM with the Large Needle Driver (400006).

Pure numpy. The arm is a modified-DH (Craig) chain whose base frame sits at the
remote centre of motion (RCM) with z up. Joint vectors are ordered
(outer_yaw [rad], outer_pitch [rad], insertion [m], roll [rad], wrist_pitch [rad],
wrist_yaw [rad]). Poses are (4, 4) homogeneous transforms in the base frame with
translations in metres.

This module holds the DH table, the joint and jaw limits, forward kinematics, the jaw
tips and touch point, Euler-angle poses and the paper's orientation rule; the closed-form
inverse is in :mod:`dvrk_gym.sim.robot.ik`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper

__all__ = [
    "DHRow",
    "PSM_DH",
    "TOOL_TIP_ROTATION",
    "JOINT_NAMES",
    "JOINT_LOWER",
    "JOINT_UPPER",
    "JOINT_LIMIT_TOLERANCE",
    "JAW_LOWER_RAD",
    "JAW_UPPER_RAD",
    "JAW_FULLY_OPEN_RAD",
    "JAW_LENGTH_M",
    "PAPER_YAWS_RAD",
    "finite_vector",
    "dh_transform",
    "link_frames",
    "last_frame",
    "dh_transforms",
    "forward_kinematics",
    "rotation_x",
    "joint_limit_violations",
    "clamp_to_joint_limits",
    "within_joint_limits",
    "jaw_tip_positions",
    "touch_point",
    "pose_from_euler",
    "euler_from_pose",
    "paper_pitch_roll",
    "nearest_paper_yaw",
]


@dataclass(frozen=True)
class DHRow:
    """One modified-DH row: T = RotX(alpha) @ TransX(a) @ RotZ(theta) @ TransZ(d).

    Attributes:
        alpha_rad: Twist about the previous x axis, radians.
        a_m: Offset along the previous x axis, metres.
        theta_offset_rad: Constant added to theta, radians.
        d_offset_m: Constant added to d, metres.
        prismatic: True if the joint value is added to d (metres), else to theta (radians).
    """

    alpha_rad: float
    a_m: float
    theta_offset_rad: float
    d_offset_m: float
    prismatic: bool


_HALF_PI = np.pi / 2
PSM_DH: tuple[DHRow, ...] = (
    DHRow(_HALF_PI, 0.0, _HALF_PI, 0.0, False),  # outer yaw
    DHRow(-_HALF_PI, 0.0, -_HALF_PI, 0.0, False),  # outer pitch
    DHRow(_HALF_PI, 0.0, 0.0, -0.4318, True),  # insertion
    DHRow(0.0, 0.0, 0.0, 0.4162, False),  # roll
    DHRow(-_HALF_PI, 0.0, -_HALF_PI, 0.0, False),  # wrist pitch
    DHRow(-_HALF_PI, 0.0091, -_HALF_PI, 0.0, False),  # wrist yaw
)


def _frozen(values: object) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False  # shared module constants must never be mutated
    return array


TOOL_TIP_ROTATION: np.ndarray = _frozen([[0, -1, 0], [0, 0, 1], [-1, 0, 0]])
JOINT_NAMES: tuple[str, ...] = ("outer_yaw", "outer_pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw")
_PRISMATIC_MASK = np.array([row.prismatic for row in PSM_DH])
_DEG = np.pi / 180.0
JOINT_LOWER: np.ndarray = _frozen([-91 * _DEG, -53 * _DEG, 0.0, -260 * _DEG, -80 * _DEG, -80 * _DEG])
JOINT_UPPER: np.ndarray = _frozen([91 * _DEG, 53 * _DEG, 0.24, 260 * _DEG, 80 * _DEG, 80 * _DEG])
JAW_LOWER_RAD: float = float(np.deg2rad(-20.0))
JAW_UPPER_RAD: float = float(np.deg2rad(80.0))
JAW_FULLY_OPEN_RAD: float = float(np.deg2rad(75.0))
JAW_LENGTH_M: float = 0.0100


def _radians_pair(degrees: tuple[float, float]) -> tuple[float, float]:
    """A (low, high) range in degrees as radians."""
    return float(np.deg2rad(degrees[0])), float(np.deg2rad(degrees[1]))


PAPER_YAWS_RAD: np.ndarray = _frozen(np.deg2rad(paper.PHASE2_YAWS_DEG))
PAPER_YAW_RANGE_RAD: tuple[float, float] = _radians_pair(paper.PHASE1_YAW_RANGE_DEG)
PAPER_PITCH_RANGE_RAD: tuple[float, float] = _radians_pair(paper.PHASE1_PITCH_RANGE_DEG)
PAPER_ROLL_RANGE_RAD: tuple[float, float] = _radians_pair(paper.PHASE1_ROLL_RANGE_DEG)
"""The paper's Phase I rotation ranges: yaw U[-90, 90], pitch U[-15, 25], roll U[-180, -150] deg."""

JOINT_LIMIT_TOLERANCE = 1e-9
"""Round-off (rad or m) allowed past a joint limit, so IK results that sit on a limit pass."""


def finite_vector(values: object, size: int | None, name: str) -> np.ndarray:
    """values as a float array of shape (size,) (None: of any shape), every element finite.

    Raises:
        ValueError: naming ``name``, if the shape is not (size,) or an element is not finite.
    """
    array = np.asarray(values, dtype=float)
    if size is not None and array.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
    if not (np.isfinite(array).all() if size is None else all(map(math.isfinite, array.tolist()))):
        raise ValueError(f"{name} must be finite, got {array}")
    return array


def dh_transform(row: DHRow, q: float) -> np.ndarray:
    """Homogeneous transform of one modified-DH link.

    Args:
        row: The DH parameters of the link.
        q: Joint value, radians (revolute) or metres (prismatic).

    Returns:
        (4, 4) transform of frame i expressed in frame i-1.
    """
    theta = row.theta_offset_rad + (0.0 if row.prismatic else q)
    d = row.d_offset_m + (q if row.prismatic else 0.0)
    ca, sa = np.cos(row.alpha_rad), np.sin(row.alpha_rad)
    ct, st = np.cos(theta), np.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, row.a_m],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


class _TableArrays:
    """A DH table's columns as arrays, for building all its link transforms at once."""

    def __init__(self, dh: tuple[DHRow, ...]) -> None:
        self.dh = dh  # kept, so that the id this is cached under stays this table's
        self.theta_offset, self.d_offset = np.array([[row.theta_offset_rad, row.d_offset_m] for row in dh]).T
        self.prismatic = np.array([row.prismatic for row in dh])
        self.revolute = ~self.prismatic
        # What a joint leaves where it does not act: offset + 0.0, as dh_transform adds it.
        self.theta_fixed, self.d_fixed = self.theta_offset + 0.0, self.d_offset + 0.0
        self.ca, self.sa = np.cos([row.alpha_rad for row in dh]), np.sin([row.alpha_rad for row in dh])
        self.template = np.zeros((len(dh), 4, 4))
        self.template[:, 0, 3], self.template[:, 1, 2], self.template[:, 2, 2] = [row.a_m for row in dh], -self.sa, self.ca
        self.template[:, 3, 3] = 1.0


_TABLE_ARRAYS: dict[int, _TableArrays] = {}
_MAX_CACHED_TABLES = 256


def _table_arrays(dh: tuple[DHRow, ...]) -> _TableArrays:
    arrays = _TABLE_ARRAYS.get(id(dh))
    if arrays is None or arrays.dh is not dh:
        if len(_TABLE_ARRAYS) >= _MAX_CACHED_TABLES:
            _TABLE_ARRAYS.clear()
        arrays = _TABLE_ARRAYS[id(dh)] = _TableArrays(dh)
    return arrays


def dh_transforms(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """The transforms of all links at once, (n, 4, 4): entry i is :func:`dh_transform`
    ``(dh[i], q[i])``, element for element the same numbers.

    Args:
        q: (n,) joint values, rad / m, one per row of ``dh`` (not checked).
        dh: DH table.
    """
    t = _table_arrays(dh)
    theta = np.add(t.theta_offset, q, out=t.theta_fixed.copy(), where=t.revolute)
    d = np.add(t.d_offset, q, out=t.d_fixed.copy(), where=t.prismatic)
    ct, st = np.cos(theta), np.sin(theta)
    transforms = t.template.copy()
    transforms[:, 0, 0], transforms[:, 0, 1] = ct, -st
    transforms[:, 1, 0], transforms[:, 1, 1], transforms[:, 1, 3] = st * t.ca, ct * t.ca, -t.sa * d
    transforms[:, 2, 0], transforms[:, 2, 1], transforms[:, 2, 3] = st * t.sa, ct * t.sa, t.ca * d
    return transforms


_EYE4 = _frozen(np.eye(4))


def _chain(q: np.ndarray, dh: tuple[DHRow, ...], frames: np.ndarray | None = None) -> np.ndarray:
    """The last frame of the chain (4, 4), filling ``frames`` (n, 4, 4) with every frame if given."""
    current = _EYE4
    for i, transform in enumerate(dh_transforms(q, dh)):
        current = current @ transform
        if frames is not None:
            frames[i] = current
    return current


def link_frames(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Frames 1..n of the chain in the base (RCM) frame.

    Args:
        q: Joint values in JOINT_NAMES order (rad / m), one per DH row.
        dh: DH table, e.g. a perturbed copy of PSM_DH.

    Returns:
        (n, 4, 4) array; entry i is frame i+1. The last frame is the wrist-yaw
        frame without the tool-tip rotation.
    """
    q = finite_vector(q, len(dh), "q")
    frames = np.empty((len(dh), 4, 4))
    _chain(q, dh, frames)
    return frames


def last_frame(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """The last frame of the chain, ``link_frames(q, dh)[-1]`` (4, 4), without the others."""
    return _chain(finite_vector(q, len(dh), "q"), dh)


def forward_kinematics(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Tool pose as reported by the dVRK: wrist-yaw frame @ tool-tip rotation.

    Args:
        q: Joint values (6,) in JOINT_NAMES order, rad / m.
        dh: DH table; pass a perturbed table to model kinematic bias.

    Returns:
        (4, 4) pose in the base frame, translation in metres.
    """
    pose = last_frame(q, dh)
    pose[:3, :3] = pose[:3, :3] @ TOOL_TIP_ROTATION
    return pose


def rotation_x(angle_rad: float) -> np.ndarray:
    """(3, 3) rotation about x by angle_rad, radians."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def joint_limit_violations(q: np.ndarray, tolerance: float) -> list[str]:
    """Human-readable descriptions (deg / mm) of the joints of q (6,) outside their limits.

    Args:
        q: (6,) joint values, rad / m.
        tolerance: How far past a limit (rad or m) still counts as within it.
    """
    if ((JOINT_LOWER - tolerance <= q) & (q <= JOINT_UPPER + tolerance)).all():
        return []
    messages = []
    for i, name in enumerate(JOINT_NAMES):
        if JOINT_LOWER[i] - tolerance <= q[i] <= JOINT_UPPER[i] + tolerance:
            continue
        scale, unit = (1e3, "mm") if _PRISMATIC_MASK[i] else (180.0 / np.pi, "deg")
        messages.append(
            f"{name} = {q[i] * scale:.3f} {unit} is outside [{JOINT_LOWER[i] * scale:.3f}, {JOINT_UPPER[i] * scale:.3f}] {unit}"
        )
    return messages


def within_joint_limits(q: np.ndarray, tolerance: float = JOINT_LIMIT_TOLERANCE) -> bool:
    """Whether every joint of q (6,), rad / m, lies within its limits.

    The default tolerance of 1e-9 (rad or m) accepts IK results that sit on a limit
    up to round-off; pass 0.0 for a strict check.
    """
    return not joint_limit_violations(finite_vector(q, 6, "q"), tolerance)


def clamp_to_joint_limits(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Clamp q (6,), rad / m, into the joint limits.

    Returns:
        (clamped q (6,), boolean mask (6,) of the joints that were changed).
    """
    q = finite_vector(q, 6, "q")
    clamped = np.clip(q, JOINT_LOWER, JOINT_UPPER)
    return clamped, clamped != q


def jaw_tip_positions(q: np.ndarray, jaw_angle_rad: float, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Positions of the two jaw tips.

    Args:
        q: (6,) joint values, rad / m.
        jaw_angle_rad: Opening angle between the jaws, radians, in [JAW_LOWER_RAD, JAW_UPPER_RAD].
        dh: DH table.

    Returns:
        (2, 3) tip positions (x, y, z) in metres in the base frame; row 0 is the jaw
        rotated by +jaw/2 about the wrist-yaw axis, row 1 by -jaw/2.
    """
    if not np.isfinite(jaw_angle_rad) or not JAW_LOWER_RAD <= jaw_angle_rad <= JAW_UPPER_RAD:
        raise ValueError(
            f"jaw angle {np.rad2deg(jaw_angle_rad):.2f} deg is outside "
            f"[{np.rad2deg(JAW_LOWER_RAD):.0f}, {np.rad2deg(JAW_UPPER_RAD):.0f}] deg"
        )
    frame6 = last_frame(q, dh)
    half = np.array([0.5, -0.5]) * jaw_angle_rad
    # A closed jaw points along y6 (the tool z axis); rotating y6 by +-half about z6.
    local_dirs = np.stack([-np.sin(half), np.cos(half), np.zeros(2)], axis=1)
    return frame6[:3, 3] + JAW_LENGTH_M * local_dirs @ frame6[:3, :3].T


def touch_point(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Lowest point (minimum base z) of the closed jaws, (x, y, z) in metres.

    The closed jaws are the segment from the wrist-yaw pivot to the closed tip, so
    the lowest point is one of its two ends.
    """
    frame6 = last_frame(q, dh)
    pivot = frame6[:3, 3]
    tip = pivot + JAW_LENGTH_M * frame6[:3, 1]
    return tip if tip[2] <= pivot[2] else pivot.copy()


def pose_from_euler(position: np.ndarray, yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Pose from a position and dVRK/tfx Euler angles, R = Rz(yaw) @ Ry(pitch) @ Rx(roll).

    Args:
        position: (x, y, z) in metres, base frame.
        yaw, pitch, roll: Radians (intrinsic ZYX).

    Returns:
        (4, 4) homogeneous transform; ValueError for a position or angle that is not finite.
    """
    position = finite_vector(position, 3, "position")
    if not (math.isfinite(yaw) and math.isfinite(pitch) and math.isfinite(roll)):
        raise ValueError(f"yaw, pitch, roll must be finite radians, got {yaw!r}, {pitch!r}, {roll!r}")
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    pose = np.eye(4)
    pose[:3, :3] = rz @ ry @ rotation_x(roll)
    pose[:3, 3] = position
    return pose


def euler_from_pose(pose: np.ndarray) -> tuple[float, float, float]:
    """Inverse of pose_from_euler.

    Returns:
        (yaw, pitch, roll) in radians; yaw, roll in (-pi, pi], pitch in [-pi/2, pi/2].
        At gimbal lock (|pitch| = pi/2) roll is set to 0 and yaw carries the rotation.
    """
    r = np.asarray(pose, dtype=float)[:3, :3]
    cos_pitch = np.hypot(r[0, 0], r[1, 0])
    pitch = float(np.arctan2(-r[2, 0], cos_pitch))
    if cos_pitch < 1e-9:
        return float(np.arctan2(-r[0, 1], r[1, 1])), pitch, 0.0
    return float(np.arctan2(r[1, 0], r[0, 0])), pitch, float(np.arctan2(r[2, 1], r[2, 2]))


_FIRST_PAPER_YAW_RAD, _PAPER_YAW_SPAN_RAD = float(PAPER_YAWS_RAD[0]), math.radians(180.0)
_PAPER_PITCH_RAD = np.deg2rad(paper.PITCH_AT_YAW_EXTREMES_DEG)  # at yaw -90 deg and +90 deg
_PAPER_ROLL_RAD = np.deg2rad(paper.ROLL_AT_YAW_EXTREMES_DEG)
_PITCH_START_RAD, _PITCH_RISE_RAD = float(_PAPER_PITCH_RAD[0]), float(np.diff(_PAPER_PITCH_RAD)[0])
_ROLL_START_RAD, _ROLL_RISE_RAD = float(_PAPER_ROLL_RAD[0]), float(np.diff(_PAPER_ROLL_RAD)[0])


def paper_pitch_roll(yaw_rad: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
    """The paper's orientation rule: pitch and roll linear in yaw (all radians).

    yaw -90 deg -> (pitch 0, roll -170) deg; yaw +90 deg -> (10, -165) deg. Works
    elementwise on arrays; ValueError for a yaw that is not finite.
    """
    if isinstance(yaw_rad, (float, int)) and not isinstance(yaw_rad, bool) and math.isfinite(yaw_rad):  # plain floats, same bits
        share = (float(yaw_rad) - _FIRST_PAPER_YAW_RAD) / _PAPER_YAW_SPAN_RAD
        return _PITCH_START_RAD + share * _PITCH_RISE_RAD, _ROLL_START_RAD + share * _ROLL_RISE_RAD
    fraction = (finite_vector(yaw_rad, None, "yaw_rad") - _FIRST_PAPER_YAW_RAD) / _PAPER_YAW_SPAN_RAD
    pitch, roll = _PITCH_START_RAD + fraction * _PITCH_RISE_RAD, _ROLL_START_RAD + fraction * _ROLL_RISE_RAD
    return (float(pitch), float(roll)) if np.ndim(pitch) == 0 else (pitch, roll)


def nearest_paper_yaw(yaw_rad: float | np.ndarray) -> float | np.ndarray:
    """The element of PAPER_YAWS_RAD closest in angle to yaw_rad (radians, elementwise; ValueError if not finite)."""
    yaw = finite_vector(yaw_rad, None, "yaw_rad")
    difference = np.angle(np.exp(1j * (yaw[..., None] - PAPER_YAWS_RAD)))
    nearest = PAPER_YAWS_RAD[np.argmin(np.abs(difference), axis=-1)]
    return float(nearest) if nearest.ndim == 0 else nearest
