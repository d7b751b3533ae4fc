"""GridTouch-v0's float paths compiled: the numbers of the Python float paths in
:mod:`~dvrk_gym.sim.robot.ik` and :mod:`~dvrk_gym.sim.robot.cables`, bit for bit, at a
fraction of their cost (the kernels are in :mod:`~dvrk_gym.sim.compiled.kernels`).

A GridTouch step evaluates the touch point about seven times (the contact search and the
simulated person's correction), and moves twice: a touch evaluation costs about 30 us in
Python floats and 3 us here, call included; a move's inverse kinematics 10 us and 3 us.
Only the first process to use them compiles the kernels (about 5 s); numba keeps the
machine code for later ones.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from dvrk_gym.sim.compiled import kernels
from dvrk_gym.sim.robot import cables, ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.kinematics import DHRow

__all__ = [
    "CableConstants",
    "forward_kinematics",
    "inverse_kinematics",
    "inverse_kinematics_clamped",
    "touch_point",
    "true_joints",
    "true_tip",
]


def link_table(dh: tuple[DHRow, ...]) -> np.ndarray:
    """The kernels' (n, 6) ``links`` of a DH table: per row cos alpha, sin alpha, a m, theta
    offset rad, d offset m, 1.0 if prismatic."""
    rows = [(math.cos(r.alpha_rad), math.sin(r.alpha_rad), r.a_m, r.theta_offset_rad, r.d_offset_m, float(r.prismatic)) for r in dh]
    return np.array(rows, dtype=np.float64)


def _arm() -> np.ndarray:
    arm = np.empty(kernels.ARM_SIZE)
    scalars = [ik._SINGULAR_TOL_M, ik._WRIST_OFFSET_M, ik._INSERTION_TO_WRIST_M, ik._ALPHA5_SIGN, ik._ROTATION_X6_COS, ik._ROTATION_X6_SIN]
    scalars += [kin.PSM_DH[4].theta_offset_rad, kin.PSM_DH[5].theta_offset_rad, ik._ROLL_LOWER_RAD, ik._ROLL_UPPER_RAD]
    scalars += [kin.JAW_LENGTH_M, cables.INSERTION_MAX_M, 2.0]  # 2.0: the squares' exponent, at run time
    arm[: kernels.ROLL_BRANCHES] = scalars
    arm[kernels.ROLL_BRANCHES : kernels.LOWER] = ik._ROLL_BRANCHES_RAD
    arm[kernels.LOWER : kernels.UPPER], arm[kernels.UPPER :] = ik._LOWER_FLOATS, ik._UPPER_FLOATS
    arm.flags.writeable = False
    return arm


ARM = _arm()
"""The nominal arm's constants, laid out as :mod:`~dvrk_gym.sim.compiled.kernels` names them."""
_OUTER_LINKS, _NOMINAL_LINKS = link_table(kin.PSM_DH[:3]), link_table(kin.PSM_DH)


class CableConstants:
    """The kernels' constants of one cable model (its instrument and configuration), packed once.

    Args:
        model: the cable model.
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
        }
        values.update({f"offset_{i}": instrument.homing_offsets[i] for i in range(6)})
        self.model = np.array([float(values[name]) for name in kernels.MODEL_FIELDS])
        self.true_links = link_table(model.true_dh)
        self.coupling = np.array(instrument.wrist_coupling, dtype=np.float64)
        self.radii = np.ascontiguousarray(cables.play_radii(config), dtype=np.float64)
        self.noise_std = cables.repeatability_std(config).tolist()


def wrist_yaw_rows(rotation: np.ndarray) -> np.ndarray:
    """The wrist-yaw frame's rotation (9,), row-major, of the tool rotation (3, 3): the kernels'
    ``r6`` (``rotation @ TOOL_TIP_ROTATION.T``, a signed permutation: exact)."""
    return (rotation @ kin.TOOL_TIP_ROTATION.T).ravel()


def true_tip(
    position: np.ndarray,
    r6: np.ndarray,
    q_ref_roll: float,
    state: np.ndarray,
    *,
    constants: CableConstants,
    fallback_command: Callable[[], Sequence[float]],
) -> np.ndarray:
    """Where the jaws' lowest point would truly be (3,) m, base frame, if the tool were
    commanded to ``position`` (3,) m (float64) with the tool-tip-to-wrist-yaw rotation ``r6``
    (9,) row-major, the roll nearest ``q_ref_roll`` rad, the cables in ``state`` (finite; not
    changed): GridTouch's probe, as ``ik.inverse_kinematics_clamped_floats``, then
    ``CableModel.peek_true_joints_floats`` and ``ik.touch_point_floats``.

    ``fallback_command`` () -> (6,) gives the command where the compiled inverse kinematics
    hands over (a pose to clamp, or singular); the cables and the touch point stay compiled.
    """
    out, c, position = np.empty(3), constants, np.ascontiguousarray(position, dtype=np.float64)
    if not kernels.true_tip(position, r6, q_ref_roll, state, c.model, c.true_links, c.coupling, c.radii, ARM, _OUTER_LINKS, out):
        command = np.asarray(fallback_command(), dtype=np.float64)
        kernels.peek_tip(command, state, c.model, c.true_links, c.coupling, c.radii, ARM, out)
    return out


def inverse_kinematics(position: np.ndarray, rotation: np.ndarray, q_ref: np.ndarray) -> list[float] | None:
    """:func:`~dvrk_gym.sim.robot.ik.inverse_kinematics_floats`, bit for bit: the joints (6,)
    rad / m of the tool pose (``rotation`` (3, 3), finite ``position`` (3,) m), roll nearest
    ``q_ref[3]``; None where that gives None (then clamp)."""
    out, position = np.empty(6), np.ascontiguousarray(position, dtype=np.float64)
    return out.tolist() if kernels.inverse_kinematics(position, wrist_yaw_rows(rotation), float(q_ref[3]), ARM, _OUTER_LINKS, out) else None


def inverse_kinematics_clamped(position: np.ndarray, rotation: np.ndarray, q_ref: np.ndarray) -> list[float]:
    """:func:`~dvrk_gym.sim.robot.ik.inverse_kinematics_clamped_floats`, bit for bit: the
    compiled :func:`inverse_kinematics` where it solves the pose, else numpy's clamped joints."""
    q = inverse_kinematics(position, rotation, q_ref)
    return ik.inverse_kinematics_clamped_floats(np.asarray(position).tolist(), rotation, q_ref) if q is None else q


def forward_kinematics(q: list[float]) -> np.ndarray:
    """:func:`~dvrk_gym.sim.robot.ik.forward_kinematics_floats` (4, 4) m of the nominal arm at
    finite joints ``q`` (6,) rad / m, bit for bit."""
    f = kernels.last_frame(np.array(q, dtype=np.float64), _NOMINAL_LINKS)
    pose = np.array([f[0:4], f[4:8], f[8:12], (0.0, 0.0, 0.0, 1.0)])
    pose[:3, :3] = pose[:3, :3] @ kin.TOOL_TIP_ROTATION
    return pose


def touch_point(q_true: np.ndarray, constants: CableConstants) -> np.ndarray:
    """:func:`~dvrk_gym.sim.robot.ik.touch_point_floats` (3,) m of the instrument whose
    ``constants`` these are at its finite true joints ``q_true`` (6,) rad / m, bit for bit."""
    out = np.empty(3)
    kernels.touch_point(np.ascontiguousarray(q_true, dtype=np.float64), constants.true_links, ARM, out)
    return out


def true_joints(
    cable: cables.CableModel, constants: CableConstants, q_cmd: list[float], noise_rng: np.random.Generator | None
) -> list[float]:
    """:meth:`CableModel.true_joints_floats <dvrk_gym.sim.robot.cables.CableModel.true_joints_floats>`,
    bit for bit, with the same random draw: move ``cable`` (whose ``constants`` these are) to the
    finite command ``q_cmd`` (6,) rad / m; its true joints (6,) rad / m."""
    state = cable.get_state()
    if math.isnan(state[0, 0]) or math.isnan(state[-1, 0]):  # no history yet: the Python path sets the cables at rest
        return cable.true_joints_floats(q_cmd, noise_rng)
    new_state, out, c = np.empty_like(state), np.empty(6), constants
    kernels.advance(np.array(q_cmd, dtype=np.float64), state, c.model, c.coupling, c.radii, ARM, new_state, out)
    cable.set_state(new_state)
    q_true = out.tolist()
    if noise_rng is not None:
        q_true = [v + n * s for v, n, s in zip(q_true, noise_rng.normal(0.0, 1.0, 6).tolist(), c.noise_std)]
    return q_true
