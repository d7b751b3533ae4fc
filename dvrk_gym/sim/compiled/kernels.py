"""The numba kernels of the float paths (:mod:`dvrk_gym.sim.compiled.float_paths` calls them).

Each is its Python float path's arithmetic, operation for operation and in the same order,
so the results are that path's bit for bit (tests/test_compiled_paths.py):

- compiled without fast-math, LLVM neither fuses multiply-adds nor reorders sums;
- ``cos``, ``sin``, ``atan2``, ``tanh``, ``sqrt`` and ``pow`` are the C library's, as in
  Python's :mod:`math` and ``**`` (LLVM may join a ``sin`` and a ``cos`` of one angle into
  glibc's ``sincos``, whose results are theirs). ``x ** 2`` takes its exponent from the ``arm`` vector at
  run time: with a constant 2 LLVM would make it ``x * x``, which differs from the C
  library's ``pow(x, 2)`` in the last bit about once in a thousand;
- Python's ``math.hypot`` is not the C library's (they differ about once in 200):
  :func:`_hypot` rounds correctly but in rare cases, as Python's does, for the unit-vector
  components it is given (no difference in 7 million pairs: measured, not proven; it does
  not scale its inputs, so it is not for values below about 1e-146 or above 1e153).

Every constant comes in as an argument (packed by ``float_paths``), none is read from another
module: numba's cache (machine code kept beside this file, or in the user's cache folder
where that is read-only) is renewed when this file changes, not when the modules its
constants come from do. For the same reason every kernel that calls another lives here.

Packed inputs:

- ``links``: (n, 6) per modified-DH row: cos alpha, sin alpha, a m, theta offset rad, d offset m, 1.0 if prismatic;
- ``arm``: the arm's constants, indexed by the names below;
- ``model``: the cable model's scalars, in the order of :data:`MODEL_FIELDS`;
- ``coupling``: (3, 2) the wrist coupling; ``radii``: (n_plays, 6) the play half-widths (rad / m);
- ``state``: (n_plays + 1, 6) the cables' state as :meth:`CableModel.get_state` gives it (finite).
"""

from __future__ import annotations

import math

import numba
import numpy as np

# Indices into ``arm``.
SINGULAR_TOL, WRIST_OFFSET, INSERTION_TO_WRIST, ALPHA5_SIGN, ROTATION_X6_COS, ROTATION_X6_SIN = 0, 1, 2, 3, 4, 5
WRIST_PITCH_OFFSET, WRIST_YAW_OFFSET, ROLL_LOWER, ROLL_UPPER, JAW_LENGTH, INSERTION_MAX, TWO = 6, 7, 8, 9, 10, 11, 12
ROLL_BRANCHES, LOWER, UPPER = 13, 18, 24  # 5, 6 and 6 entries
ARM_SIZE = 30
# The order of the ``model`` vector's entries.
MODEL_FIELDS: tuple[str, ...] = ("settle_lag", "outer_gain_yaw", "outer_gain_pitch", "outer_stretch_rad", "sag_m", "wrist_stretch")
MODEL_FIELDS += tuple(f"offset_{i}" for i in range(6))
MODEL_FIELDS += ("outer_unloaded_yaw_rad", "outer_unloaded_pitch_rad", "outer_scale_rad", "wrist_scale_rad")

_jit = numba.njit(cache=True, fastmath=False, nogil=True)


@_jit
def _then_link(f, link, q):
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
def last_frame(q, links):
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
def _square(x, two):
    """Python's ``x ** 2``: the C library's pow, ``two`` (2.0) given at run time so that LLVM
    cannot make it ``x * x``."""
    return x**two


@_jit
def _split(x):
    """Veltkamp's split of ``x`` into two halves of 26 bits: x == hi + lo exactly."""
    t = x * 134217729.0  # 2 ** 27 + 1
    hi = t - (t - x)
    return hi, x - hi


@_jit
def _two_product(x, y):
    """Dekker's exact product: x * y == p + e exactly, p the rounded product."""
    x_hi, x_lo = _split(x)
    y_hi, y_lo = _split(y)
    p = x * y
    return p, ((x_hi * y_hi - p) + x_hi * y_lo + x_lo * y_hi) + x_lo * y_lo


@_jit
def _hypot(a, b):
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
def _wrap(angle):
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
def inverse_kinematics(p, r6, q_ref_roll, arm, outer_links, out):
    """ik.inverse_kinematics_floats into ``out`` (6,); False where it gives None. ``p`` (3,) m,
    ``r6`` (9,) the wrist-yaw frame's rotation, row-major."""
    two = arm[TWO]
    n0, n1, n2 = r6[2], r6[5], r6[8]
    along = p[0] * n0 + p[1] * n1 + p[2] * n2
    r0, r1, r2 = p[0] - along * n0, p[1] - along * n1, p[2] - along * n2
    radial_norm = math.sqrt(_square(r0, two) + _square(r1, two) + _square(r2, two))
    if radial_norm < arm[SINGULAR_TOL]:
        return False
    x0, x1, x2 = r0 / radial_norm, r1 / radial_norm, r2 / radial_norm
    w = arm[WRIST_OFFSET]
    p50, p51, p52 = p[0] - w * x0, p[1] - w * x1, p[2] - w * x2
    shaft_length = math.sqrt(_square(p50, two) + _square(p51, two) + _square(p52, two))
    if shaft_length < arm[SINGULAR_TOL]:
        return False
    s0, s1, s2 = p50 / shaft_length, p51 / shaft_length, p52 / shaft_length
    yaw, pitch = math.atan2(s0, -s2), -math.atan2(s1, _hypot(s0, s2))
    insertion = arm[INSERTION_TO_WRIST] + shaft_length
    z50, z51, z52 = x1 * n2 - x2 * n1, x2 * n0 - x0 * n2, x0 * n1 - x1 * n0
    r5 = (x0, n0, z50, x1, n1, z51, x2, n2, z52)
    outer = np.empty(3)
    outer[0], outer[1], outer[2] = yaw, pitch, insertion
    f3 = last_frame(outer, outer_links)
    r3 = (f3[0], f3[1], f3[2], f3[4], f3[5], f3[6], f3[8], f3[9], f3[10])
    s = arm[ALPHA5_SIGN]
    m02 = r3[0] * r5[2] + r3[3] * r5[5] + r3[6] * r5[8]
    m12 = r3[1] * r5[2] + r3[4] * r5[5] + r3[7] * r5[8]
    m20 = r3[2] * r5[0] + r3[5] * r5[3] + r3[8] * r5[6]
    m21 = r3[2] * r5[1] + r3[5] * r5[4] + r3[8] * r5[7]
    roll, wrist_pitch = math.atan2(s * m02, -s * m12), math.atan2(s * m20, s * m21)
    n00 = r5[0] * r6[0] + r5[3] * r6[3] + r5[6] * r6[6]
    n10 = r5[1] * r6[0] + r5[4] * r6[3] + r5[7] * r6[6]
    n20 = r5[2] * r6[0] + r5[5] * r6[3] + r5[8] * r6[6]
    wrist_yaw = math.atan2(arm[ROTATION_X6_COS] * n10 + arm[ROTATION_X6_SIN] * n20, n00) - arm[WRIST_YAW_OFFSET]
    wrist_pitch -= arm[WRIST_PITCH_OFFSET]
    roll = _wrap(roll)
    out[0], out[1], out[2], out[4], out[5] = yaw, pitch, insertion, _wrap(wrist_pitch), _wrap(wrist_yaw)
    # The roll branch nearest the reference, among those within roll's limits if any (the first of equals).
    any_within = False
    for k in range(ROLL_BRANCHES, ROLL_BRANCHES + 5):
        branch = roll + arm[k]
        if arm[ROLL_LOWER] <= branch <= arm[ROLL_UPPER]:
            any_within = True
    best, best_distance, found = 0.0, 0.0, False
    for k in range(ROLL_BRANCHES, ROLL_BRANCHES + 5):
        branch = roll + arm[k]
        if any_within and not arm[ROLL_LOWER] <= branch <= arm[ROLL_UPPER]:
            continue
        if not found or abs(branch - q_ref_roll) < best_distance:  # min()'s: the first candidate, then strictly smaller
            best, best_distance, found = branch, abs(branch - q_ref_roll), True
    out[3] = best
    for i in range(6):  # noqa: SIM110 (numba compiles no generator expressions)
        if not arm[LOWER + i] <= out[i] <= arm[UPPER + i]:
            return False
    return True


@_jit
def advance(q_cmd, state, model, coupling, radii, arm, new_state, out):
    """CableModel._advance_floats for the command ``q_cmd`` (6,): the cables' state after the move
    into ``new_state`` (as ``state``: the plays, then the motors), its noiseless true joints into ``out``."""
    n_plays = state.shape[0] - 1
    motors = q_cmd.copy()
    if model[0] != 0.0:
        for i in range(4, 6):
            motors[i] += model[0] * (state[n_plays, i] - motors[i])
    new_state[n_plays] = motors
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
            new_state[k, j] = play
            total = m - play if k == 0 else total + (m - play)
        q[j] = m - total / n_plays
    # _errors_floats: outer stretch, gravity sag, wrist stretch through the coupling (model: MODEL_FIELDS' order).
    scale = model[14]
    stretch0 = model[1] * model[3] * math.tanh((q[0] - model[12]) / scale)
    stretch1 = model[2] * model[3] * math.tanh((q[1] - model[13]) / scale)
    yaw, pitch, insertion = q[0], q[1], q[2]
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    shaft0, shaft1, shaft2 = sy * cp, -sp, -cy * cp
    along = -shaft2
    down0, down1, down2 = -along * shaft0, -along * shaft1, -1.0 - along * shaft2
    factor = model[4] / arm[INSERTION_MAX] * _square(insertion / arm[INSERTION_MAX], arm[TWO])
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
def touch_point(q, links, arm, out):
    """ik.touch_point_floats into ``out`` (3,) m for joints ``q`` (6,) of the chain ``links``."""
    jaw_length = arm[JAW_LENGTH]
    f = last_frame(q, links)
    pivot_z, tip_z = f[11], f[11] + jaw_length * f[9]
    if tip_z <= pivot_z:
        out[0], out[1], out[2] = f[3] + jaw_length * f[1], f[7] + jaw_length * f[5], tip_z
    else:
        out[0], out[1], out[2] = f[3], f[7], pivot_z


@_jit
def true_tip(position, r6, q_ref_roll, state, model, true_links, coupling, radii, arm, outer_links, out):
    """Where the jaws would truly be (``out``, (3,) m) if commanded to ``position`` (3,) m at the
    wrist-yaw rotation ``r6`` now, the cables in ``state`` (not changed); False (``out``
    untouched) where the inverse kinematics hands over."""
    command = np.empty(6)
    if not inverse_kinematics(position, r6, q_ref_roll, arm, outer_links, command):
        return False
    peek_tip(command, state, model, true_links, coupling, radii, arm, out)
    return True


@_jit
def peek_tip(command, state, model, true_links, coupling, radii, arm, out):
    """Where the jaws would truly be (``out``, (3,) m) after a noiseless move to ``command`` (6,), the cables in ``state`` (not changed)."""
    q_true = np.empty(6)
    advance(command, state, model, coupling, radii, arm, np.empty_like(state), q_true)
    touch_point(q_true, true_links, arm, out)
