"""GridTouch-v0's touch evaluation compiled with numba: where the jaws would truly be if the
tool were commanded to a position now, the cables' state untouched.

The Python float path it replaces on the hot loop
(:func:`~dvrk_gym.sim.robot.ik.inverse_kinematics_floats`,
:meth:`~dvrk_gym.sim.robot.cables.CableModel.peek_true_joints_floats`,
:func:`~dvrk_gym.sim.robot.ik.touch_point_floats`), operation for operation and in the same
order, so the results are that path's bit for bit (tests/test_compiled_touch.py):

- compiled without fast-math, LLVM neither fuses multiply-adds nor reorders sums;
- ``cos``, ``sin``, ``atan2``, ``tanh``, ``sqrt`` and ``pow`` are the C library's, as in
  Python's :mod:`math` and ``**``. ``x ** 2`` takes its exponent from the ``model`` vector
  at run time: with a constant 2 LLVM would make it ``x * x``, which differs from the C
  library's ``pow(x, 2)`` in the last bit about once in a thousand;
- Python's ``math.hypot`` is not the C library's (they differ about once in 200):
  :func:`_hypot` rounds correctly, as Python's does but in rare cases (no difference in
  6 million pairs, measured).

A GridTouch step evaluates the touch point about seven times (the contact search and the
simulated person's correction): about 30 us each in Python floats, 3 us compiled, call
included. Numba caches the machine code beside this file (or in the user's cache folder
where that is read-only), so only the first process compiles it (about 3 s).

Packed inputs (:class:`TouchConstants` builds the constant ones once per cable model):

- ``links``: (n, 6) per modified-DH row: cos alpha, sin alpha, a m, theta offset rad, d offset m, 1.0 if prismatic;
- ``model``: (17,) the cable model's scalars, see :data:`MODEL_FIELDS`;
- ``coupling``: (3, 2) the wrist coupling; ``radii``: (n_plays, 6) the play half-widths (rad / m);
- ``state``: (n_plays + 1, 6) the cables' state as :meth:`CableModel.get_state` gives it (finite).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numba
import numpy as np

from dvrk_gym.sim.robot import cables, ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.kinematics import DHRow

__all__ = ["MODEL_FIELDS", "TouchConstants", "inverse_kinematics", "inverse_kinematics_clamped", "link_table", "true_tip"]

# "two" is the exponent of the squares, read at run time (see above).
MODEL_FIELDS = ("settle_lag", "outer_gain_yaw", "outer_gain_pitch", "outer_stretch_rad", "sag_m", "wrist_stretch")
MODEL_FIELDS += tuple(f"offset_{i}" for i in range(6))
MODEL_FIELDS += ("outer_unloaded_yaw_rad", "outer_unloaded_pitch_rad", "outer_scale_rad", "wrist_scale_rad", "two")
"""The order of the ``model`` vector's entries."""


def link_table(dh: tuple[DHRow, ...]) -> np.ndarray:
    """The packed (n, 6) ``links`` of a DH table (see the module's docstring)."""
    rows = [(math.cos(r.alpha_rad), math.sin(r.alpha_rad), r.a_m, r.theta_offset_rad, r.d_offset_m, float(r.prismatic)) for r in dh]
    return np.array(rows, dtype=np.float64)


class TouchConstants:
    """The constant inputs of :func:`true_tip` for one cable model, packed once.

    Args:
        model: the cable model whose instrument and configuration they describe.
    """

    def __init__(self, model: cables.CableModel) -> None:
        config, instrument = model.config, model.instrument
        values = {
            "settle_lag": config.wrist_settle_lag,
            "outer_gain_yaw": instrument.outer_gains[0],
            "outer_gain_pitch": instrument.outer_gains[1],
            "outer_stretch_rad": config.outer_stretch_rad,
            "sag_m": config.sag_m,
            "wrist_stretch": config.wrist_stretch,
            "outer_unloaded_yaw_rad": cables.OUTER_UNLOADED_RAD[0],
            "outer_unloaded_pitch_rad": cables.OUTER_UNLOADED_RAD[1],
            "outer_scale_rad": cables.OUTER_STRETCH_SCALE_RAD,
            "wrist_scale_rad": cables.WRIST_STRETCH_SCALE_RAD,
            "two": 2.0,
        }
        values.update({f"offset_{i}": instrument.homing_offsets[i] for i in range(6)})
        self.model = np.array([float(values[name]) for name in MODEL_FIELDS])
        self.true_links = link_table(model.true_dh)
        self.coupling = np.array(instrument.wrist_coupling, dtype=np.float64)
        self.radii = np.ascontiguousarray(cables.play_radii(config), dtype=np.float64)


_NOMINAL_LINKS = link_table(kin.PSM_DH)
_OUTER_LINKS = link_table(kin.PSM_DH[:3])
# The inverse kinematics' constants, in the order of _IK's entries.
_IK = np.array(
    [
        ik._SINGULAR_TOL_M,
        ik._WRIST_OFFSET_M,
        ik._INSERTION_TO_WRIST_M,
        ik._ALPHA5_SIGN,
        ik._ROTATION_X6_COS,
        ik._ROTATION_X6_SIN,
        kin.PSM_DH[4].theta_offset_rad,
        kin.PSM_DH[5].theta_offset_rad,
        ik._ROLL_LOWER_RAD,
        ik._ROLL_UPPER_RAD,
        kin.JAW_LENGTH_M,
        cables.INSERTION_MAX_M,
    ]
)
_ROLL_BRANCHES = np.array(ik._ROLL_BRANCHES_RAD)
_LOWER = np.array(ik._LOWER_FLOATS)
_UPPER = np.array(ik._UPPER_FLOATS)

_jit = numba.njit(cache=True, fastmath=False, nogil=True)


@_jit
def _then_link(f, link, q):  # type: ignore[no-untyped-def]
    ca, sa, a, theta_offset, d_offset = link[0], link[1], link[2], link[3], link[4]
    if link[5] != 0.0:
        theta, d = theta_offset + 0.0, d_offset + q
    else:
        theta, d = theta_offset + q, d_offset + 0.0
    ct, st = math.cos(theta), math.sin(theta)
    t10, t11, t13, t20, t21, t23 = st * ca, ct * ca, -sa * d, st * sa, ct * sa, ca * d
    a0, a1, a2, a3, b0, b1, b2, b3, c0, c1, c2, c3 = f
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


@_jit
def _last_frame(q, links):  # type: ignore[no-untyped-def]
    """ik.last_frame_floats: the chain's last frame (row-major 3x4) for joints ``q`` (n,)."""
    first = links[0]
    ca, sa, a, theta_offset, d_offset = first[0], first[1], first[2], first[3], first[4]
    if first[5] != 0.0:
        theta, d = theta_offset + 0.0, d_offset + q[0]
    else:
        theta, d = theta_offset + q[0], d_offset + 0.0
    ct, st = math.cos(theta), math.sin(theta)
    f = (ct, -st, 0.0, a, st * ca, ct * ca, -sa, -sa * d, st * sa, ct * sa, ca, ca * d)
    for i in range(1, links.shape[0]):
        f = _then_link(f, links[i], q[i])
    return f


@_jit
def _square(x, two):  # type: ignore[no-untyped-def]
    """Python's ``x ** 2``: the C library's pow, ``two`` (2.0) given at run time so that LLVM
    cannot make it ``x * x``."""
    return x**two


@_jit
def _split(x):  # type: ignore[no-untyped-def]
    """Veltkamp's split of ``x`` into two halves of 26 bits: x == hi + lo exactly."""
    t = x * 134217729.0  # 2 ** 27 + 1
    hi = t - (t - x)
    return hi, x - hi


@_jit
def _two_product(x, y):  # type: ignore[no-untyped-def]
    """Dekker's exact product: x * y == p + e exactly, p the rounded product."""
    x_hi, x_lo = _split(x)
    y_hi, y_lo = _split(y)
    p = x * y
    return p, ((x_hi * y_hi - p) + x_hi * y_lo + x_lo * y_hi) + x_lo * y_lo


@_jit
def _hypot(a, b):  # type: ignore[no-untyped-def]
    """sqrt(a^2 + b^2) of finite ``a``, ``b``, correctly rounded but in rare cases, as
    Python's math.hypot is (the C library's is within an ulp, and differs from it in about
    one case in 200): the sum of squares in double-double, its rounded square root, and one
    Newton correction from the exact residual."""
    x, y = abs(a), abs(b)
    if x < y:
        x, y = y, x
    if y == 0.0:
        return x
    p, p_err = _two_product(x, x)
    q, q_err = _two_product(y, y)
    s = p + q
    virtual = s - p
    s_err = (p - (s - virtual)) + (q - virtual)  # Knuth's two-sum: p + q == s + s_err exactly
    h = math.sqrt(s)
    hh, hh_err = _two_product(h, h)
    residual = ((s - hh) - hh_err) + (s_err + (p_err + q_err))
    return h + residual / (2.0 * h)


@_jit
def _wrap(angle):  # type: ignore[no-untyped-def]
    """ik._wrap: Python's float % (fmod, then the divisor's sign), written out."""
    x, period = -angle + math.pi, 2 * math.pi
    mod = np.fmod(x, period)
    if mod != 0.0:
        if (period < 0.0) != (mod < 0.0):
            mod += period
    else:
        mod = math.copysign(0.0, period)
    return -mod + math.pi


@_jit
def _inverse_kinematics(p, r6, q_ref_roll, two, out):  # type: ignore[no-untyped-def]
    """ik.inverse_kinematics_floats into ``out`` (6,); False where it gives None."""
    n0, n1, n2 = r6[2], r6[5], r6[8]
    along = p[0] * n0 + p[1] * n1 + p[2] * n2
    r0, r1, r2 = p[0] - along * n0, p[1] - along * n1, p[2] - along * n2
    radial_norm = math.sqrt(_square(r0, two) + _square(r1, two) + _square(r2, two))
    if radial_norm < _IK[0]:
        return False
    x0, x1, x2 = r0 / radial_norm, r1 / radial_norm, r2 / radial_norm
    w = _IK[1]
    p50, p51, p52 = p[0] - w * x0, p[1] - w * x1, p[2] - w * x2
    shaft_length = math.sqrt(_square(p50, two) + _square(p51, two) + _square(p52, two))
    if shaft_length < _IK[0]:
        return False
    s0, s1, s2 = p50 / shaft_length, p51 / shaft_length, p52 / shaft_length
    yaw, pitch = math.atan2(s0, -s2), -math.atan2(s1, _hypot(s0, s2))
    insertion = _IK[2] + shaft_length
    z50, z51, z52 = x1 * n2 - x2 * n1, x2 * n0 - x0 * n2, x0 * n1 - x1 * n0
    r5 = (x0, n0, z50, x1, n1, z51, x2, n2, z52)
    outer = np.empty(3)
    outer[0], outer[1], outer[2] = yaw, pitch, insertion
    f3 = _last_frame(outer, _OUTER_LINKS)
    r3 = (f3[0], f3[1], f3[2], f3[4], f3[5], f3[6], f3[8], f3[9], f3[10])
    s = _IK[3]
    m02 = r3[0] * r5[2] + r3[3] * r5[5] + r3[6] * r5[8]
    m12 = r3[1] * r5[2] + r3[4] * r5[5] + r3[7] * r5[8]
    m20 = r3[2] * r5[0] + r3[5] * r5[3] + r3[8] * r5[6]
    m21 = r3[2] * r5[1] + r3[5] * r5[4] + r3[8] * r5[7]
    roll, wrist_pitch = math.atan2(s * m02, -s * m12), math.atan2(s * m20, s * m21)
    n00 = r5[0] * r6[0] + r5[3] * r6[3] + r5[6] * r6[6]
    n10 = r5[1] * r6[0] + r5[4] * r6[3] + r5[7] * r6[6]
    n20 = r5[2] * r6[0] + r5[5] * r6[3] + r5[8] * r6[6]
    wrist_yaw = math.atan2(_IK[4] * n10 + _IK[5] * n20, n00) - _IK[7]
    wrist_pitch -= _IK[6]
    roll = _wrap(roll)
    out[0], out[1], out[2], out[4], out[5] = yaw, pitch, insertion, _wrap(wrist_pitch), _wrap(wrist_yaw)
    # The roll branch nearest the reference, among those within roll's limits if any (the first of equals).
    any_within = False
    for offset in _ROLL_BRANCHES:
        branch = roll + offset
        if _IK[8] <= branch <= _IK[9]:
            any_within = True
    best, best_distance = 0.0, math.inf
    for offset in _ROLL_BRANCHES:
        branch = roll + offset
        if (not any_within or _IK[8] <= branch <= _IK[9]) and abs(branch - q_ref_roll) < best_distance:
            best, best_distance = branch, abs(branch - q_ref_roll)
    out[3] = best
    for i in range(6):  # noqa: SIM110 (numba compiles no generator expressions)
        if not _LOWER[i] <= out[i] <= _UPPER[i]:
            return False
    return True


@_jit
def _peek_true_joints(q_cmd, state, model, coupling, radii, out):  # type: ignore[no-untyped-def]
    """CableModel._advance_floats' noiseless true joints for the command ``q_cmd`` (6,) into ``out``."""
    n_plays = state.shape[0] - 1
    motors = q_cmd.copy()
    if model[0] != 0.0:
        for i in range(4, 6):
            motors[i] += model[0] * (state[n_plays, i] - motors[i])
    q = np.empty(6)
    for j in range(6):
        m = motors[j]
        total = 0.0
        for k in range(n_plays):
            play, r = state[k, j], radii[k, j]
            if play < m - r:
                play = m - r
            elif play > m + r:
                play = m + r
            total = m - play if k == 0 else total + (m - play)
        q[j] = m - total / n_plays
    # _errors_floats: outer stretch, gravity sag, wrist stretch through the coupling.
    scale = model[14]
    stretch0 = model[1] * model[3] * math.tanh((q[0] - model[12]) / scale)
    stretch1 = model[2] * model[3] * math.tanh((q[1] - model[13]) / scale)
    yaw, pitch, insertion = q[0], q[1], q[2]
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    shaft0, shaft1, shaft2 = sy * cp, -sp, -cy * cp
    along = -shaft2
    down0, down1, down2 = -along * shaft0, -along * shaft1, -1.0 - along * shaft2
    factor = model[4] / _IK[11] * _square(insertion / _IK[11], model[16])
    rot0, rot1, rot2 = factor * down0, factor * down1, factor * down2
    sag0 = (cy * cp * rot0 + sy * cp * rot2) / (cp * cp)
    sag1 = -sy * sp * rot0 - cp * rot1 + cy * sp * rot2
    w = model[15]
    wrist0 = model[5] * w * math.tanh(q[4] / w)
    wrist1 = model[5] * w * math.tanh(q[5] / w)
    errors = (stretch0 + sag0, stretch1 + sag1, 0.0)
    for j in range(3):
        out[j] = q[j] + model[6 + j] + errors[j]
    for j in range(3):
        out[3 + j] = q[3 + j] + model[9 + j] + (coupling[j, 0] * wrist0 + coupling[j, 1] * wrist1)


@_jit
def _touch_point(q, links, jaw_length, out):  # type: ignore[no-untyped-def]
    """ik.touch_point_floats into ``out`` (3,)."""
    f = _last_frame(q, links)
    pivot_z, tip_z = f[11], f[11] + jaw_length * f[9]
    if tip_z <= pivot_z:
        out[0], out[1], out[2] = f[3] + jaw_length * f[1], f[7] + jaw_length * f[5], tip_z
    else:
        out[0], out[1], out[2] = f[3], f[7], pivot_z


@_jit
def _true_tip(position, r6, q_ref_roll, state, model, true_links, coupling, radii, command, out):  # type: ignore[no-untyped-def]
    """Compiled body of :func:`true_tip`; False (nothing written to ``out``) where the inverse kinematics hands over."""
    if not _inverse_kinematics(position, r6, q_ref_roll, model[16], command):
        return False
    q_true = np.empty(6)
    _peek_true_joints(command, state, model, coupling, radii, q_true)
    _touch_point(q_true, true_links, _IK[10], out)
    return True


@_jit
def _peek_tip(command, state, model, true_links, coupling, radii, out):  # type: ignore[no-untyped-def]
    q_true = np.empty(6)
    _peek_true_joints(command, state, model, coupling, radii, q_true)
    _touch_point(q_true, true_links, _IK[10], out)


def true_tip(
    position: np.ndarray,
    r6: np.ndarray,
    q_ref_roll: float,
    state: np.ndarray,
    constants: TouchConstants,
    fallback_command: Callable[[], Sequence[float]],
) -> np.ndarray:
    """Where the jaws' lowest point would truly be (3,) m, base frame, if the tool were
    commanded to ``position`` (3,) m with the tool-tip-to-wrist-yaw rotation ``r6`` (9,)
    row-major, the roll nearest ``q_ref_roll`` rad, the cables in ``state`` (finite).

    ``fallback_command`` () -> (6,) gives the command where the compiled inverse kinematics
    hands over (a pose to clamp, or singular); the cables and the touch point stay compiled.
    """
    command, out = np.empty(6), np.empty(3)
    if not _true_tip(
        position, r6, q_ref_roll, state, constants.model, constants.true_links, constants.coupling, constants.radii, command, out
    ):
        _peek_tip(
            np.asarray(fallback_command(), dtype=np.float64),
            state,
            constants.model,
            constants.true_links,
            constants.coupling,
            constants.radii,
            out,
        )
    return out


def inverse_kinematics(position: np.ndarray, rotation: np.ndarray, q_ref: np.ndarray) -> list[float] | None:
    """:func:`~dvrk_gym.sim.robot.ik.inverse_kinematics_floats` compiled, its numbers bit for bit:
    the joints (6,) rad / m of the tool pose (``rotation`` (3, 3), finite ``position`` (3,) m,
    float64), roll nearest ``q_ref[3]``; None where that path gives None (then clamp)."""
    r6 = (rotation @ kin.TOOL_TIP_ROTATION.T).ravel()  # a signed permutation: exact
    out, position = np.empty(6), np.ascontiguousarray(position, dtype=np.float64)
    return out.tolist() if _inverse_kinematics(position, r6, float(q_ref[3]), 2.0, out) else None


def inverse_kinematics_clamped(position: np.ndarray, rotation: np.ndarray, q_ref: np.ndarray) -> list[float]:
    """:func:`~dvrk_gym.sim.robot.ik.inverse_kinematics_clamped_floats` with the compiled
    :func:`inverse_kinematics`: its joints where it solves the pose, else numpy's clamped ones."""
    q = inverse_kinematics(position, rotation, q_ref)
    return ik.inverse_kinematics_clamped_floats(position.tolist(), rotation, q_ref) if q is None else q
