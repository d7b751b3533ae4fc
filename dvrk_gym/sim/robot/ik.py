"""Closed-form inverse kinematics of the nominal dVRK PSM (:data:`~dvrk_gym.sim.robot.kinematics.PSM_DH`).

The dVRK controller turns a commanded tool pose into joint commands with this inverse of
:func:`~dvrk_gym.sim.robot.kinematics.forward_kinematics`. Poses are (4, 4) transforms in
the base (RCM) frame, metres; joint vectors follow
:data:`~dvrk_gym.sim.robot.kinematics.JOINT_NAMES` (rad, insertion in m).
"""

from __future__ import annotations

import math

import numpy as np

from dvrk_gym.sim.robot.kinematics import (
    JAW_LENGTH_M,
    JOINT_LIMIT_TOLERANCE,
    JOINT_LOWER,
    JOINT_UPPER,
    PSM_DH,
    TOOL_TIP_ROTATION,
    DHRow,
    clamp_to_joint_limits,
    dh_transforms,
    finite_vector,
    joint_limit_violations,
    rotation_x,
)

__all__ = ["UnreachablePoseError", "inverse_kinematics", "inverse_kinematics_clamped"]

# The wrist-pitch point lies (insertion - 15.6 mm) past the RCM along the shaft; this
# is that +15.6 mm (sum of the insertion and roll d offsets, negated).
_INSERTION_TO_WRIST_M = -(PSM_DH[2].d_offset_m + PSM_DH[3].d_offset_m)
_WRIST_OFFSET_M = PSM_DH[5].a_m
_SINGULAR_TOL_M = 1e-6
_OUTER_DH = PSM_DH[:3]  # yaw, pitch, insertion: the rows that place the wrist
_ALPHA5_SIGN = float(np.sign(np.sin(PSM_DH[4].alpha_rad)))
_ROTATION_X6 = rotation_x(PSM_DH[5].alpha_rad)
_ROLL_BRANCHES_RAD = (2 * np.pi * np.arange(-2, 3)).tolist()
_ROLL_LOWER_RAD, _ROLL_UPPER_RAD = float(JOINT_LOWER[3]), float(JOINT_UPPER[3])
_EYE3 = np.eye(3)
_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])


class UnreachablePoseError(ValueError):
    """Raised when no joint configuration within limits reaches a requested pose."""


def _wrap(angle_rad: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    # Python's float % is np.remainder's arithmetic (fmod, then the divisor's sign).
    return -((-float(angle_rad) + math.pi) % (2 * math.pi)) + math.pi


def _zxz_outer_angles(m: np.ndarray, s: float) -> tuple[float, float]:
    """Angles (a, c) of m = Rz(a) @ Rx(b) @ Rz(c) for a known b, given s = sign(sin(b)) != 0."""
    return float(np.arctan2(s * m[0, 2], -s * m[1, 2])), float(np.arctan2(s * m[2, 0], s * m[2, 1]))


def _nonsingular_norm(vector: np.ndarray, why_singular: str) -> np.floating:
    """The norm of vector, m; UnreachablePoseError if it is too short to give a direction.

    Args:
        vector: (3,) metres.
        why_singular: What a short vector means, with ``{mm:.4f}`` where its length (mm) goes.
    """
    norm = np.sqrt(vector.dot(vector))  # np.linalg.norm's own formula for a vector, without its checks
    if norm < _SINGULAR_TOL_M:
        raise UnreachablePoseError("pose is geometrically unreachable: " + why_singular.format(mm=norm * 1e3))
    return norm


def _solve_branch(p6: np.ndarray, r6: np.ndarray, x5_sign: float, shaft_sign: float) -> np.ndarray:
    """Closed-form IK for one geometric branch of the nominal PSM (roll in (-pi, pi])."""
    n = r6[:, 2]  # wrist-yaw axis z6; in this chain z6 == y5
    # p6 - p5 = a * x5 (x5: common normal of z5 and z6) and the shaft through the RCM
    # and p5 lies in span(x5, n), so the part of p6 normal to n points along +-x5.
    radial = p6 - (p6 @ n) * n
    radial_norm = _nonsingular_norm(radial, "the wrist-yaw axis passes within {mm:.4f} mm of the RCM (target too close to the RCM?)")
    x5 = x5_sign * radial / radial_norm
    p5 = p6 - _WRIST_OFFSET_M * x5
    shaft_length = _nonsingular_norm(p5, "the wrist-pitch point is {mm:.4f} mm from the RCM, so the shaft direction is undefined")
    shaft = shaft_sign * p5 / shaft_length
    # From FK: shaft = (sin(yaw) cos(pitch), -sin(pitch), -cos(yaw) cos(pitch)).
    yaw = np.arctan2(shaft[0], -shaft[2])
    pitch = -np.arctan2(shaft[1], np.hypot(shaft[0], shaft[2]))
    insertion = _INSERTION_TO_WRIST_M + shaft_sign * shaft_length
    # Right-handed frame 5: z5 = x5 x y5 (spelled out because np.cross is slow for 3-vectors).
    r5 = np.empty((3, 3))
    r5[:, 0], r5[:, 1] = x5, n
    r5[:, 2] = [x5[1] * n[2] - x5[2] * n[1], x5[2] * n[0] - x5[0] * n[2], x5[0] * n[1] - x5[1] * n[0]]
    t0, t1, t2 = dh_transforms(np.array([yaw, pitch, insertion]), _OUTER_DH)
    r3 = (t0 @ t1 @ t2)[:3, :3]
    # R35 = Rz(q4) Rx(alpha5) Rz(q5 + offset5) because alpha4 = 0 and a4 = a5 = 0.
    roll, wrist_pitch = _zxz_outer_angles(r3.T @ r5, _ALPHA5_SIGN)
    # R56 = Rx(alpha6) Rz(q6 + offset6).
    r56 = _ROTATION_X6.T @ (r5.T @ r6)
    wrist_yaw = np.arctan2(r56[1, 0], r56[0, 0]) - PSM_DH[5].theta_offset_rad
    wrist_pitch -= PSM_DH[4].theta_offset_rad
    return np.array([yaw, pitch, insertion, _wrap(roll), _wrap(wrist_pitch), _wrap(wrist_yaw)])


def _choose_roll(q: np.ndarray, q_ref: np.ndarray | None) -> np.ndarray:
    """Pick the 2*pi branch of roll: within limits and closest to q_ref[3] if given."""
    if q_ref is None:
        return q
    # In Python floats (the same sums and comparisons as on arrays, without their overhead);
    # min() takes the first of equal distances, as np.argmin does.
    roll, reference = float(q[3]), float(q_ref[3])
    branches = [roll + offset for offset in _ROLL_BRANCHES_RAD]
    candidates = [b for b in branches if _ROLL_LOWER_RAD <= b <= _ROLL_UPPER_RAD] or branches
    q = q.copy()
    q[3] = min(candidates, key=lambda b: abs(b - reference))
    return q


def _validate_pose(pose: np.ndarray) -> np.ndarray:
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise ValueError(f"pose must have shape (4, 4), got {pose.shape}")
    if not all(map(math.isfinite, pose.ravel().tolist())):
        raise ValueError("pose must be finite")
    rotation = pose[:3, :3]
    orthonormality_error = np.abs(rotation.T @ rotation - _EYE3).max()
    bottom_row_error = np.abs(pose[3] - _BOTTOM_ROW).max()
    (a, b, c), (d, e, f), (g, h, i) = rotation.tolist()
    determinant = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if orthonormality_error > 1e-6 or bottom_row_error > 1e-9 or determinant < 0:
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
    q_ref = None if q_ref is None else finite_vector(q_ref, 6, "q_ref")
    p6, r6 = pose[:3, 3], pose[:3, :3] @ TOOL_TIP_ROTATION.T
    first_violations: list[str] = []
    # Branch (+1, +1) is the physical one; the others only occur with the wrist
    # pitch point less than 15.6 mm past the RCM (insertion < 15.6 mm).
    for x5_sign, shaft_sign in ((1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)):
        q = _choose_roll(_solve_branch(p6, r6, x5_sign, shaft_sign), q_ref)
        violations = joint_limit_violations(q, JOINT_LIMIT_TOLERANCE)
        if not violations:
            return q
        first_violations = first_violations or violations
    raise UnreachablePoseError("pose needs joints outside their limits: " + "; ".join(first_violations))


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
        q_ref = None if q_ref is None else finite_vector(q_ref, 6, "q_ref")
        q = _choose_roll(_solve_branch(pose[:3, 3], pose[:3, :3] @ TOOL_TIP_ROTATION.T, 1.0, 1.0), q_ref)
        return clamp_to_joint_limits(q)


# --- the touch evaluation in Python floats ------------------------------------------------
# A contact search or a simulated person asks "where would the jaws be if commanded there?"
# a dozen times a step; on 3- to 6-element arrays numpy's per-call overhead is most of the
# cost. These do the same arithmetic in Python floats, except that numpy's 3x3 / 4x4
# products (BLAS) use fused multiply-adds and math.atan2 / math.hypot can differ from
# numpy's in the last bit: results agree to a few ulps, not bit for bit
# (tests/test_float_paths.py bounds the difference). GridTouch-v0 runs them compiled
# (dvrk_gym/sim/compiled, the same numbers bit for bit); these stay as their reference.

Frame = tuple[float, ...]
"""The top three rows of a homogeneous transform, row-major: (r00, r01, r02, x, r10, ..., z)."""

_LINK_CONSTANTS: dict[int, tuple[tuple[DHRow, ...], list[tuple[float, float, float, float, float, bool]]]] = {}


def _link_constants(dh: tuple[DHRow, ...]) -> list[tuple[float, float, float, float, float, bool]]:
    """Per row of ``dh``: (cos alpha, sin alpha, a m, theta offset rad, d offset m, prismatic), cached per table."""
    entry = _LINK_CONSTANTS.get(id(dh))
    if entry is None or entry[0] is not dh:
        if len(_LINK_CONSTANTS) >= 256:
            _LINK_CONSTANTS.clear()
        rows = [(math.cos(r.alpha_rad), math.sin(r.alpha_rad), r.a_m, r.theta_offset_rad, r.d_offset_m, r.prismatic) for r in dh]
        entry = _LINK_CONSTANTS[id(dh)] = (dh, rows)
    return entry[1]


def _link_terms(link: tuple[float, float, float, float, float, bool], q: float) -> tuple[float, ...]:
    """(ct, st, st ca, ct ca, -sa d, st sa, ct sa, ca d) of one modified-DH link at joint value
    ``q`` (rad or m): its rows are (ct, -st, 0, a), (st ca, ct ca, -sa, -sa d), (st sa, ct sa, ca, ca d)."""
    ca, sa, _, theta_offset, d_offset, prismatic = link
    theta, d = (theta_offset + 0.0, d_offset + q) if prismatic else (theta_offset + q, d_offset + 0.0)
    ct, st = math.cos(theta), math.sin(theta)
    return ct, st, st * ca, ct * ca, -sa * d, st * sa, ct * sa, ca * d


def _then_link(c: Frame, link: tuple[float, float, float, float, float, bool], q: float) -> Frame:
    """Frame ``c`` composed with one modified-DH link at joint value ``q`` (rad or m)."""
    ca, sa, a = link[0], link[1], link[2]
    ct, st, t10, t11, t13, t20, t21, t23 = _link_terms(link, q)
    a0, a1, a2, a3, b0, b1, b2, b3, c0, c1, c2, c3 = c
    return (
        a0 * ct + a1 * t10 + a2 * t20,
        -a0 * st + a1 * t11 + a2 * t21,
        -a1 * sa + a2 * ca,
        a0 * a + a1 * t13 + a2 * t23 + a3,
        b0 * ct + b1 * t10 + b2 * t20,
        -b0 * st + b1 * t11 + b2 * t21,
        -b1 * sa + b2 * ca,
        b0 * a + b1 * t13 + b2 * t23 + b3,
        c0 * ct + c1 * t10 + c2 * t20,
        -c0 * st + c1 * t11 + c2 * t21,
        -c1 * sa + c2 * ca,
        c0 * a + c1 * t13 + c2 * t23 + c3,
    )


def last_frame_floats(q: list[float], dh: tuple[DHRow, ...] = PSM_DH) -> Frame:
    """The chain's last frame (as :func:`~dvrk_gym.sim.robot.kinematics.last_frame`) for
    joint values ``q`` (rad / m, one per row of ``dh``, at least one; finite: not checked),
    in floats. The first link's rows are the first frame (numpy's identity @ link can turn
    a -0.0 into 0.0; nothing else differs)."""
    links = _link_constants(dh)
    first = links[0]
    ct, st, t10, t11, t13, t20, t21, t23 = _link_terms(first, q[0])
    frame: Frame = (ct, -st, 0.0, first[2], t10, t11, -first[1], t13, t20, t21, first[0], t23)
    for link, value in zip(links[1:], q[1:]):
        frame = _then_link(frame, link, value)
    return frame


def touch_point_floats(q: list[float], dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """:func:`~dvrk_gym.sim.robot.kinematics.touch_point` (x, y, z) m, computed in floats."""
    f = last_frame_floats(q, dh)
    pivot_z, tip_z = f[11], f[11] + JAW_LENGTH_M * f[9]
    if tip_z <= pivot_z:
        return np.array([f[3] + JAW_LENGTH_M * f[1], f[7] + JAW_LENGTH_M * f[5], tip_z])
    return np.array([f[3], f[7], pivot_z])


def forward_kinematics_floats(q: list[float], dh: tuple[DHRow, ...] = PSM_DH) -> np.ndarray:
    """:func:`~dvrk_gym.sim.robot.kinematics.forward_kinematics` (4, 4) m of finite joints
    ``q`` (6,) rad / m (not checked), the chain in floats: a few ulps from it."""
    f = last_frame_floats(q, dh)
    pose = np.array([f[0:4], f[4:8], f[8:12], (0.0, 0.0, 0.0, 1.0)])
    pose[:3, :3] = pose[:3, :3] @ TOOL_TIP_ROTATION
    return pose


_ROTATION_X6_COS, _ROTATION_X6_SIN = float(_ROTATION_X6[1, 1]), float(_ROTATION_X6[2, 1])
_OUTER_LINKS = PSM_DH[:3]


def _physical_branch_floats(p6: list[float], r6: list[float]) -> list[float] | None:
    """:func:`_solve_branch` of the physical branch (+1, +1) in floats, for the position
    ``p6`` (3,) m and wrist-yaw rotation ``r6`` (row-major 9) ; None where the numpy
    path would raise (a singular pose)."""
    n0, n1, n2 = r6[2], r6[5], r6[8]
    along = p6[0] * n0 + p6[1] * n1 + p6[2] * n2
    radial = [p6[0] - along * n0, p6[1] - along * n1, p6[2] - along * n2]
    radial_norm = math.sqrt(radial[0] ** 2 + radial[1] ** 2 + radial[2] ** 2)
    if radial_norm < _SINGULAR_TOL_M:
        return None
    x0, x1, x2 = radial[0] / radial_norm, radial[1] / radial_norm, radial[2] / radial_norm
    p5 = [p6[0] - _WRIST_OFFSET_M * x0, p6[1] - _WRIST_OFFSET_M * x1, p6[2] - _WRIST_OFFSET_M * x2]
    shaft_length = math.sqrt(p5[0] ** 2 + p5[1] ** 2 + p5[2] ** 2)
    if shaft_length < _SINGULAR_TOL_M:
        return None
    s0, s1, s2 = p5[0] / shaft_length, p5[1] / shaft_length, p5[2] / shaft_length
    yaw, pitch = math.atan2(s0, -s2), -math.atan2(s1, math.hypot(s0, s2))
    insertion = _INSERTION_TO_WRIST_M + shaft_length
    z5 = (x1 * n2 - x2 * n1, x2 * n0 - x0 * n2, x0 * n1 - x1 * n0)
    r5 = (x0, n0, z5[0], x1, n1, z5[1], x2, n2, z5[2])
    f3 = last_frame_floats([yaw, pitch, insertion], _OUTER_LINKS)
    r3 = (f3[0], f3[1], f3[2], f3[4], f3[5], f3[6], f3[8], f3[9], f3[10])
    s = _ALPHA5_SIGN
    # (r3.T @ r5)[i, j] = column i of r3 . column j of r5, and likewise (r5.T @ r6).
    m02 = r3[0] * r5[2] + r3[3] * r5[5] + r3[6] * r5[8]
    m12 = r3[1] * r5[2] + r3[4] * r5[5] + r3[7] * r5[8]
    m20 = r3[2] * r5[0] + r3[5] * r5[3] + r3[8] * r5[6]
    m21 = r3[2] * r5[1] + r3[5] * r5[4] + r3[8] * r5[7]
    roll, wrist_pitch = math.atan2(s * m02, -s * m12), math.atan2(s * m20, s * m21)
    n00 = r5[0] * r6[0] + r5[3] * r6[3] + r5[6] * r6[6]
    n10 = r5[1] * r6[0] + r5[4] * r6[3] + r5[7] * r6[6]
    n20 = r5[2] * r6[0] + r5[5] * r6[3] + r5[8] * r6[6]
    wrist_yaw = math.atan2(_ROTATION_X6_COS * n10 + _ROTATION_X6_SIN * n20, n00) - PSM_DH[5].theta_offset_rad
    wrist_pitch -= PSM_DH[4].theta_offset_rad
    return [yaw, pitch, insertion, _wrap(roll), _wrap(wrist_pitch), _wrap(wrist_yaw)]


_LOWER_FLOATS = (JOINT_LOWER - JOINT_LIMIT_TOLERANCE).tolist()
_UPPER_FLOATS = (JOINT_UPPER + JOINT_LIMIT_TOLERANCE).tolist()


def inverse_kinematics_floats(position: list[float], rotation: np.ndarray, q_ref: np.ndarray) -> list[float] | None:
    """:func:`inverse_kinematics` of the pose (``rotation`` (3, 3), ``position`` (3,) m) in
    floats, roll nearest ``q_ref[3]``; None where that is not the physical branch's
    solution within the limits (then use :func:`inverse_kinematics_clamped`). The rotation
    must be a rotation and the position finite (not checked)."""
    r6 = (rotation @ TOOL_TIP_ROTATION.T).ravel().tolist()  # signed permutation: exact
    q = _physical_branch_floats(position, r6)
    if q is None:
        return None
    roll, reference = q[3], float(q_ref[3])
    branches = [roll + offset for offset in _ROLL_BRANCHES_RAD]
    candidates = [b for b in branches if _ROLL_LOWER_RAD <= b <= _ROLL_UPPER_RAD] or branches
    q[3] = min(candidates, key=lambda b: abs(b - reference))
    if all(lo <= v <= hi for lo, v, hi in zip(_LOWER_FLOATS, q, _UPPER_FLOATS)):
        return q
    return None


def inverse_kinematics_clamped_floats(position: list[float], rotation: np.ndarray, q_ref: np.ndarray) -> list[float]:
    """The joints (6,) rad / m of :func:`inverse_kinematics_clamped` for the pose (``rotation``
    (3, 3), ``position`` (3,) m): :func:`inverse_kinematics_floats`'s where it solves the pose,
    else numpy's clamped solution (the 4x4 pose is built only then)."""
    q = inverse_kinematics_floats(position, rotation, q_ref)
    if q is not None:
        return q
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rotation, position
    return inverse_kinematics_clamped(pose, q_ref=q_ref)[0].tolist()
