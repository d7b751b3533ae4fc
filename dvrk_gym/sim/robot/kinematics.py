"""Kinematics of the dVRK PSM with the Large Needle Driver (400006).

Pure numpy. The arm is a modified-DH (Craig) chain whose base frame sits at the
remote centre of motion (RCM) with z up. Joint vectors are ordered
(outer_yaw [rad], outer_pitch [rad], insertion [m], roll [rad], wrist_pitch [rad],
wrist_yaw [rad]). Poses are (4, 4) homogeneous transforms in the base frame with
translations in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DHRow", "PSM_DH", "TOOL_TIP_ROTATION", "JOINT_NAMES", "JOINT_LOWER", "JOINT_UPPER",
    "JAW_LOWER_RAD", "JAW_UPPER_RAD", "JAW_FULLY_OPEN_RAD", "JAW_LENGTH_M",
    "PAPER_YAWS_RAD", "UnreachablePoseError", "dh_transform", "link_frames",
    "forward_kinematics", "inverse_kinematics", "clamp_to_joint_limits",
    "within_joint_limits", "jaw_tip_positions", "touch_point", "pose_from_euler",
    "euler_from_pose", "paper_pitch_roll", "nearest_paper_yaw",
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
JOINT_NAMES: tuple[str, ...] = (
    "outer_yaw", "outer_pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw")
_PRISMATIC_MASK = np.array([row.prismatic for row in PSM_DH])
_DEG = np.pi / 180.0
JOINT_LOWER: np.ndarray = _frozen(
    [-91 * _DEG, -53 * _DEG, 0.0, -260 * _DEG, -80 * _DEG, -80 * _DEG])
JOINT_UPPER: np.ndarray = _frozen(
    [91 * _DEG, 53 * _DEG, 0.24, 260 * _DEG, 80 * _DEG, 80 * _DEG])
JAW_LOWER_RAD: float = float(np.deg2rad(-20.0))
JAW_UPPER_RAD: float = float(np.deg2rad(80.0))
JAW_FULLY_OPEN_RAD: float = float(np.deg2rad(75.0))
JAW_LENGTH_M: float = 0.0100
PAPER_YAWS_RAD: np.ndarray = _frozen(np.deg2rad([-90.0, -45.0, 0.0, 45.0, 90.0]))
PAPER_YAW_RANGE_RAD: tuple[float, float] = (float(np.deg2rad(-90.0)), float(np.deg2rad(90.0)))
PAPER_PITCH_RANGE_RAD: tuple[float, float] = (float(np.deg2rad(-15.0)), float(np.deg2rad(25.0)))
PAPER_ROLL_RANGE_RAD: tuple[float, float] = (float(np.deg2rad(-180.0)), float(np.deg2rad(-150.0)))
"""The paper's Phase I rotation ranges: yaw U[-90, 90], pitch U[-15, 25], roll U[-180, -150] deg."""

# The wrist-pitch point lies (insertion - 15.6 mm) past the RCM along the shaft; this
# is that +15.6 mm (sum of the insertion and roll d offsets, negated).
_INSERTION_TO_WRIST_M = -(PSM_DH[2].d_offset_m + PSM_DH[3].d_offset_m)
_WRIST_OFFSET_M = PSM_DH[5].a_m
_LIMIT_TOL = 1e-9  # absorbs round-off when IK recovers a configuration on a limit
_SINGULAR_TOL_M = 1e-6


class UnreachablePoseError(ValueError):
    """Raised when no joint configuration within limits reaches a requested pose."""


def _as_vector(values: object, size: int, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
    if not np.all(np.isfinite(array)):
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
    return np.array([
        [ct, -st, 0.0, row.a_m],
        [st * ca, ct * ca, -sa, -sa * d],
        [st * sa, ct * sa, ca, ca * d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def link_frames(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Frames 1..n of the chain in the base (RCM) frame.

    Args:
        q: Joint values in JOINT_NAMES order (rad / m), one per DH row.
        dh: DH table, e.g. a perturbed copy of PSM_DH.

    Returns:
        (n, 4, 4) array; entry i is frame i+1. The last frame is the wrist-yaw
        frame without the tool-tip rotation.
    """
    q = _as_vector(q, len(dh), "q")
    frames = np.empty((len(dh), 4, 4))
    current = np.eye(4)
    for i, (row, qi) in enumerate(zip(dh, q)):
        current = current @ dh_transform(row, qi)
        frames[i] = current
    return frames


def forward_kinematics(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Tool pose as reported by the dVRK: wrist-yaw frame @ tool-tip rotation.

    Args:
        q: Joint values (6,) in JOINT_NAMES order, rad / m.
        dh: DH table; pass a perturbed table to model kinematic bias.

    Returns:
        (4, 4) pose in the base frame, translation in metres.
    """
    pose = link_frames(q, dh)[-1]
    pose[:3, :3] = pose[:3, :3] @ TOOL_TIP_ROTATION
    return pose


def _wrap(angle_rad: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return float(-np.remainder(-angle_rad + np.pi, 2 * np.pi) + np.pi)


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _zxz_outer_angles(m: np.ndarray, b: float) -> tuple[float, float]:
    """Angles (a, c) of m = Rz(a) @ Rx(b) @ Rz(c) for a known b with sin(b) != 0."""
    s = np.sign(np.sin(b))
    return float(np.arctan2(s * m[0, 2], -s * m[1, 2])), float(np.arctan2(s * m[2, 0], s * m[2, 1]))


def _solve_branch(p6: np.ndarray, r6: np.ndarray, x5_sign: float, shaft_sign: float) -> np.ndarray:
    """Closed-form IK for one geometric branch of the nominal PSM (roll in (-pi, pi])."""
    n = r6[:, 2]  # wrist-yaw axis z6; in this chain z6 == y5
    # p6 - p5 = a * x5 (x5: common normal of z5 and z6) and the shaft through the RCM
    # and p5 lies in span(x5, n), so the part of p6 normal to n points along +-x5.
    radial = p6 - (p6 @ n) * n
    radial_norm = np.linalg.norm(radial)
    if radial_norm < _SINGULAR_TOL_M:
        raise UnreachablePoseError(
            "pose is geometrically unreachable: the wrist-yaw axis passes within "
            f"{radial_norm * 1e3:.4f} mm of the RCM (target too close to the RCM?)")
    x5 = x5_sign * radial / radial_norm
    p5 = p6 - _WRIST_OFFSET_M * x5
    shaft_length = np.linalg.norm(p5)
    if shaft_length < _SINGULAR_TOL_M:
        raise UnreachablePoseError(
            "pose is geometrically unreachable: the wrist-pitch point is "
            f"{shaft_length * 1e3:.4f} mm from the RCM, so the shaft direction is undefined")
    shaft = shaft_sign * p5 / shaft_length
    # From FK: shaft = (sin(yaw) cos(pitch), -sin(pitch), -cos(yaw) cos(pitch)).
    yaw = np.arctan2(shaft[0], -shaft[2])
    pitch = -np.arctan2(shaft[1], np.hypot(shaft[0], shaft[2]))
    insertion = _INSERTION_TO_WRIST_M + shaft_sign * shaft_length
    # Right-handed frame 5: z5 = x5 x y5 (spelled out because np.cross is slow for 3-vectors).
    z5 = np.array([x5[1] * n[2] - x5[2] * n[1], x5[2] * n[0] - x5[0] * n[2],
                   x5[0] * n[1] - x5[1] * n[0]])
    r5 = np.column_stack([x5, n, z5])
    r3 = (dh_transform(PSM_DH[0], yaw) @ dh_transform(PSM_DH[1], pitch)
          @ dh_transform(PSM_DH[2], insertion))[:3, :3]
    # R35 = Rz(q4) Rx(alpha5) Rz(q5 + offset5) because alpha4 = 0 and a4 = a5 = 0.
    roll, wrist_pitch = _zxz_outer_angles(r3.T @ r5, PSM_DH[4].alpha_rad)
    # R56 = Rx(alpha6) Rz(q6 + offset6).
    r56 = _rot_x(PSM_DH[5].alpha_rad).T @ (r5.T @ r6)
    wrist_yaw = np.arctan2(r56[1, 0], r56[0, 0]) - PSM_DH[5].theta_offset_rad
    wrist_pitch -= PSM_DH[4].theta_offset_rad
    return np.array([yaw, pitch, insertion, _wrap(roll), _wrap(wrist_pitch), _wrap(wrist_yaw)])


def _limit_violations(q: np.ndarray, tolerance: float) -> list[str]:
    """Human-readable descriptions (deg / mm) of the joints outside their limits."""
    messages = []
    for i, name in enumerate(JOINT_NAMES):
        if JOINT_LOWER[i] - tolerance <= q[i] <= JOINT_UPPER[i] + tolerance:
            continue
        scale, unit = (1e3, "mm") if _PRISMATIC_MASK[i] else (180.0 / np.pi, "deg")
        messages.append(
            f"{name} = {q[i] * scale:.3f} {unit} is outside "
            f"[{JOINT_LOWER[i] * scale:.3f}, {JOINT_UPPER[i] * scale:.3f}] {unit}")
    return messages


def _choose_roll(q: np.ndarray, q_ref: np.ndarray | None) -> np.ndarray:
    """Pick the 2*pi branch of roll: within limits and closest to q_ref[3] if given."""
    if q_ref is None:
        return q
    branches = q[3] + 2 * np.pi * np.arange(-2, 3)
    in_limits = (branches >= JOINT_LOWER[3]) & (branches <= JOINT_UPPER[3])
    candidates = branches[in_limits] if in_limits.any() else branches
    q = q.copy()
    q[3] = candidates[np.argmin(np.abs(candidates - q_ref[3]))]
    return q


def _validate_pose(pose: np.ndarray) -> np.ndarray:
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise ValueError(f"pose must have shape (4, 4), got {pose.shape}")
    if not np.all(np.isfinite(pose)):
        raise ValueError("pose must be finite")
    rotation = pose[:3, :3]
    orthonormality_error = np.abs(rotation.T @ rotation - np.eye(3)).max()
    bottom_row_error = np.abs(pose[3] - (0.0, 0.0, 0.0, 1.0)).max()
    if orthonormality_error > 1e-6 or bottom_row_error > 1e-9 or np.linalg.det(rotation) < 0:
        raise ValueError("pose must be a rigid transform (orthonormal, det +1, last row 0 0 0 1)")
    return pose


def inverse_kinematics(pose: np.ndarray, q_ref: np.ndarray | None = None) -> np.ndarray:
    """Closed-form inverse kinematics of the nominal PSM (PSM_DH).

    Args:
        pose: (4, 4) target tool pose in the base frame (metres), as from forward_kinematics.
        q_ref: Optional (6,) reference configuration; only its roll (index 3) is used,
            to choose among the 2*pi-equivalent roll solutions.

    Returns:
        (6,) joint values in JOINT_NAMES order (rad / m), within joint limits. Without
        q_ref the roll lies in (-pi, pi].

    Raises:
        ValueError: pose or q_ref is malformed or non-finite.
        UnreachablePoseError: the pose is singular or needs a joint outside its limits.
    """
    pose = _validate_pose(pose)
    q_ref = None if q_ref is None else _as_vector(q_ref, 6, "q_ref")
    p6, r6 = pose[:3, 3], pose[:3, :3] @ TOOL_TIP_ROTATION.T
    first_violations: list[str] = []
    # Branch (+1, +1) is the physical one; the others only occur with the wrist
    # pitch point less than 15.6 mm past the RCM (insertion < 15.6 mm).
    for x5_sign, shaft_sign in ((1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)):
        q = _choose_roll(_solve_branch(p6, r6, x5_sign, shaft_sign), q_ref)
        violations = _limit_violations(q, _LIMIT_TOL)
        if not violations:
            return q
        first_violations = first_violations or violations
    raise UnreachablePoseError(
        "pose needs joints outside their limits: " + "; ".join(first_violations))


def inverse_kinematics_clamped(pose: np.ndarray, q_ref: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Inverse kinematics that clamps into the joint limits instead of refusing.

    For a reachable pose this equals :func:`inverse_kinematics`. Otherwise the physical
    branch's solution is clamped joint by joint, so the tool goes as near as its limits
    allow (the pose is then not reached exactly).

    Returns:
        (q (6,) within the limits, boolean mask (6,) of the joints that were clamped).

    Raises:
        ValueError: pose or q_ref is malformed or non-finite.
        UnreachablePoseError: the pose is singular (e.g. at the RCM).
    """
    try:
        q = inverse_kinematics(pose, q_ref)
        return q, np.zeros(6, dtype=bool)
    except UnreachablePoseError:
        pose = _validate_pose(pose)
        q_ref = None if q_ref is None else _as_vector(q_ref, 6, "q_ref")
        q = _choose_roll(_solve_branch(pose[:3, 3], pose[:3, :3] @ TOOL_TIP_ROTATION.T, 1.0, 1.0), q_ref)
        return clamp_to_joint_limits(q)


def within_joint_limits(q: np.ndarray, tolerance: float = _LIMIT_TOL) -> bool:
    """Whether every joint of q (6,), rad / m, lies within its limits.

    The default tolerance of 1e-9 (rad or m) accepts IK results that sit on a limit
    up to round-off; pass 0.0 for a strict check.
    """
    return not _limit_violations(_as_vector(q, 6, "q"), tolerance)


def clamp_to_joint_limits(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Clamp q (6,), rad / m, into the joint limits.

    Returns:
        (clamped q (6,), boolean mask (6,) of the joints that were changed).
    """
    q = _as_vector(q, 6, "q")
    clamped = np.clip(q, JOINT_LOWER, JOINT_UPPER)
    return clamped, clamped != q


def jaw_tip_positions(
    q: np.ndarray, jaw_angle_rad: float, dh: tuple[DHRow, ...] = PSM_DH
) -> np.ndarray:
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
            f"[{np.rad2deg(JAW_LOWER_RAD):.0f}, {np.rad2deg(JAW_UPPER_RAD):.0f}] deg")
    frame6 = link_frames(q, dh)[-1]
    half = np.array([0.5, -0.5]) * jaw_angle_rad
    # A closed jaw points along y6 (the tool z axis); rotating y6 by +-half about z6.
    local_dirs = np.stack([-np.sin(half), np.cos(half), np.zeros(2)], axis=1)
    return frame6[:3, 3] + JAW_LENGTH_M * local_dirs @ frame6[:3, :3].T


def touch_point(q: np.ndarray, dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """Lowest point (minimum base z) of the closed jaws, (x, y, z) in metres.

    The closed jaws are the segment from the wrist-yaw pivot to the closed tip, so
    the lowest point is one of its two ends.
    """
    frame6 = link_frames(q, dh)[-1]
    pivot = frame6[:3, 3]
    tip = pivot + JAW_LENGTH_M * frame6[:3, 1]
    return tip if tip[2] <= pivot[2] else pivot.copy()


def pose_from_euler(position: np.ndarray, yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Pose from a position and dVRK/tfx Euler angles, R = Rz(yaw) @ Ry(pitch) @ Rx(roll).

    Args:
        position: (x, y, z) in metres, base frame.
        yaw, pitch, roll: Radians (intrinsic ZYX).

    Returns:
        (4, 4) homogeneous transform.
    """
    position = _as_vector(position, 3, "position")
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    pose = np.eye(4)
    pose[:3, :3] = rz @ ry @ _rot_x(roll)
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


_PAPER_YAW_SPAN_RAD = np.deg2rad(180.0)
_PAPER_PITCH_RAD = np.deg2rad([0.0, 10.0])  # at yaw -90 deg and +90 deg
_PAPER_ROLL_RAD = np.deg2rad([-170.0, -165.0])


def paper_pitch_roll(yaw_rad: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
    """The paper's orientation rule: pitch and roll linear in yaw (all radians).

    yaw -90 deg -> (pitch 0, roll -170) deg; yaw +90 deg -> (10, -165) deg. Works
    elementwise on arrays.
    """
    fraction = (np.asarray(yaw_rad, dtype=float) - PAPER_YAWS_RAD[0]) / _PAPER_YAW_SPAN_RAD
    pitch = _PAPER_PITCH_RAD[0] + fraction * np.diff(_PAPER_PITCH_RAD)[0]
    roll = _PAPER_ROLL_RAD[0] + fraction * np.diff(_PAPER_ROLL_RAD)[0]
    if np.ndim(pitch) == 0:
        return float(pitch), float(roll)
    return pitch, roll


def nearest_paper_yaw(yaw_rad: float | np.ndarray) -> float | np.ndarray:
    """The element of PAPER_YAWS_RAD closest in angle to yaw_rad (radians, elementwise)."""
    yaw = np.asarray(yaw_rad, dtype=float)
    difference = np.angle(np.exp(1j * (yaw[..., None] - PAPER_YAWS_RAD)))
    nearest = PAPER_YAWS_RAD[np.argmin(np.abs(difference), axis=-1)]
    return float(nearest) if nearest.ndim == 0 else nearest
