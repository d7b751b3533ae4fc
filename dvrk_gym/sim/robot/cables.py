"""Why the dVRK misses: the cable model between joint commands and true joint angles.

The dVRK controller turns a commanded tool pose into joint commands with the *nominal*
inverse kinematics, and its encoders (at the motors) report those commands, so the
reported pose is ``forward_kinematics(q_cmd, PSM_DH)``; unless the wrist settles short
(``BiasConfig.wrist_settle_lag``): then the wrist motors stop short of their commands, the
encoders report where (:meth:`CableModel.measured_joints`), and the cables follow the
motors. Between the motors and the joints
run cables that stretch, slip and stick; the instrument itself is machined to a
tolerance. :class:`CableModel` turns the commands, and their history, into the joint
angles the arm really takes, ``q_true``; with the instrument's real DH table
(:attr:`CableModel.true_dh`) these give the pose the cameras see:
``forward_kinematics(q_true, model.true_dh)``.

The error terms (magnitudes from :class:`~dvrk_gym.sim.robot.bias.BiasConfig`):

- homing offsets (per instrument): constant joint offsets;
- tool kinematic error (per instrument): the true DH table;
- outer-joint cable stretch: outer yaw / pitch errors that grow, and saturate, with the
  joint's distance from the pose where its cables are unloaded;
- wrist cable stretch: coupled roll / wrist-pitch / wrist-yaw errors from the wrist
  deflection, so the tip error depends on orientation and not only on position;
- gravity sag of the shaft, growing with insertion and with the shaft's tilt;
- hysteresis: a Prandtl-Ishlinskii sum of play operators per joint (state!);
- repeatability noise: a fresh draw per move.

The per-instrument terms are drawn in :func:`~dvrk_gym.sim.robot.bias.draw_instrument`;
the per-move ones are the functions below. Joint vectors follow
:data:`dvrk_gym.sim.robot.kinematics.JOINT_NAMES` (rad, insertion in m).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig, Instrument, draw_instrument

__all__ = ["CableModel", "outer_stretch", "wrist_stretch", "gravity_sag"]
__all__ += ["play_update", "hysteresis_output", "repeatability_std", "play_radii"]

_N_JOINTS = 6
_OUTER = slice(0, 2)  # outer yaw, outer pitch
_WRIST = slice(3, 6)  # roll, wrist pitch, wrist yaw
_WRIST_BENDING = slice(4, 6)  # wrist pitch, wrist yaw
_DEG = np.pi / 180.0


def _frozen(values: object) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False  # module constants are shared by every model
    return array


# Cable stretch saturates: wire rope is soft while its strands bed in and stiffer under
# load, so stretch ~ scale * tanh(deflection / scale). These scales (rad) are where the
# stretch curve bends over.
OUTER_STRETCH_SCALE_RAD = 8.0 * _DEG
# Outer (yaw, pitch) pose where the arm, as mounted, loads its outer cables least, rad.
# Where it lies on a real arm depends on its mounting and balance; here it is near one
# corner of the paper's workspace (which spans about 1-27 deg of outer yaw and -28-0 deg
# of outer pitch), so the stretch grows across the workspace, and differently for each
# tool yaw (the wrist, and with it the shaft, sits on a different side of the jaw tip
# for each), which makes the rigid-fit residual differ between the paper's yaws.
OUTER_UNLOADED_RAD = _frozen(np.array([5.0, -22.0]) * _DEG)
WRIST_STRETCH_SCALE_RAD = 30.0 * _DEG
INSERTION_MAX_M = float(kin.JOINT_UPPER[2])
_OUTER_UNLOADED_FLOATS = OUTER_UNLOADED_RAD.tolist()
# Lever arms (m) from each joint's motion to the jaw tip in the paper's workspace, used
# to express tip repeatability as joint noise: RCM to tissue for the outer joints, the
# jaw's distance off the shaft axis for roll, wrist offset + jaw for wrist pitch, the jaw
# for wrist yaw.
TIP_LEVER_ARMS_M = _frozen([0.17, 0.17, 1.0, 0.010, 0.019, 0.010])
INSERTION_JOINT = 2
ROTARY_JOINTS = (0, 1, 3, 4, 5)
# Hysteresis: each joint's loop is a sum of equally weighted play operators whose
# half-widths are these fractions of the largest; a sum of plays gives the rounded loops
# and minor loops of friction-loaded cables instead of one hard dead band.
PLAY_FRACTIONS = _frozen([0.25, 0.5, 0.75, 1.0])


# --- the per-move error terms ------------------------------------------------------------


def outer_stretch(q: np.ndarray, config: BiasConfig, gains: np.ndarray) -> np.ndarray:
    """Outer yaw / pitch errors from the stretch of their drive cables, (2,) rad.

    The outer joints are driven by capstans and cables loaded by the arm's imperfectly
    balanced weight. The load, and so the stretch, is zero at OUTER_UNLOADED_RAD and
    grows either side of it; the cable stiffens under load, so the error grows and then
    saturates: gain * A * tanh((q - q_unloaded) / s). A smooth, position-dependent
    distortion of the workspace: most of the error a rigid fit cannot remove. (At the
    ``paper`` magnitude it is larger than cable stretch alone would be: see the notes
    above ``_PAPER`` in :mod:`dvrk_gym.sim.robot.bias`.)

    Args:
        q: (6,) joint values, rad / m.
        config: Supplies A = outer_stretch_rad.
        gains: (2,) per-instrument factors near 1.
    """
    deflection = (q[_OUTER] - OUTER_UNLOADED_RAD) / OUTER_STRETCH_SCALE_RAD
    return gains * config.outer_stretch_rad * np.tanh(deflection)


def wrist_stretch(q: np.ndarray, config: BiasConfig, coupling: np.ndarray) -> np.ndarray:
    """Coupled roll / wrist-pitch / wrist-yaw errors from wrist-cable stretch, (3,) rad.

    Each of the wrist-pitch and wrist-yaw cable pairs stretches by
    k * s * tanh(deflection / s) (compliance k = wrist_stretch, saturation s =
    WRIST_STRETCH_SCALE_RAD); the coupling matrix spreads the stretch over the three
    wrist joints, since the yaw cables run over the pitch pulleys and all cables twist
    the shaft. Roll's own angle drives no stretch: its drive carries almost no load (the
    tool is nearly symmetric about the shaft), and leaving it out keeps the error
    continuous where the inverse kinematics wraps roll at +-pi.
    """
    scale = WRIST_STRETCH_SCALE_RAD
    stretch = config.wrist_stretch * scale * np.tanh(q[4:6] / scale)
    return coupling @ stretch


def gravity_sag(q: np.ndarray, config: BiasConfig) -> np.ndarray:
    """Outer yaw / pitch errors (2,) rad equivalent to the shaft sagging under gravity.

    The shaft hangs from the RCM like a cantilever: it turns toward the vertical by an
    angle proportional to insertion^2 and to the sine of its tilt from the vertical (zero
    when it hangs straight down); sag_m is the tip drop of a horizontal shaft at full
    insertion. The rotation is expressed as outer yaw / pitch changes by least squares
    through the Jacobian of the shaft direction.
    """
    yaw, pitch, insertion = q[0], q[1], q[2]
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    shaft = np.array([sy * cp, -sp, -cy * cp])  # unit, from the RCM toward the tip
    down = np.array([0.0, 0.0, -1.0])
    toward_down = down - (down @ shaft) * shaft  # |.| = sin(tilt from the vertical)
    full_insertion_angle_rad = config.sag_m / INSERTION_MAX_M
    rotation = full_insertion_angle_rad * (insertion / INSERTION_MAX_M) ** 2 * toward_down
    jacobian = np.array([[cy * cp, 0.0, sy * cp], [-sy * sp, -cp, cy * sp]]).T
    return _least_squares(jacobian, rotation)


_lstsq_gufunc: Any
try:  # numpy >= 2: lstsq's own LAPACK routine, without the wrapper's checks and error state
    from numpy.linalg._umath_linalg import lstsq as _lstsq_gufunc
except ImportError:  # pragma: no cover - older numpy names it differently
    _lstsq_gufunc = None


def _least_squares(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.lstsq(a, b, rcond=None)[0]`` for a (m, n) float matrix and a (m,) vector, the
    same numbers (the same LAPACK call, gelsd, with the same cut-off) at a fraction of the
    wrapper's cost; tests/test_step_speed.py checks that they agree."""
    if _lstsq_gufunc is None:
        return np.linalg.lstsq(a, b, rcond=None)[0]
    rcond = np.finfo(np.float64).eps * max(a.shape)
    return _lstsq_gufunc(a, b[:, np.newaxis], rcond, signature="ddd->ddid")[0][:, 0]


def _gravity_sag_floats(q: list[float], config: BiasConfig) -> tuple[float, float]:
    """:func:`gravity_sag` (2,) rad in floats. The Jacobian's columns, (cy cp, 0, sy cp) and
    (-sy sp, -cp, cy sp), are orthogonal, so its least squares is two projections; it
    differs from gelsd's in the last bits."""
    yaw, pitch, insertion = q[0], q[1], q[2]
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    shaft = (sy * cp, -sp, -cy * cp)
    along = -shaft[2]  # down . shaft, down = (0, 0, -1)
    toward_down = (-along * shaft[0], -along * shaft[1], -1.0 - along * shaft[2])
    factor = config.sag_m / INSERTION_MAX_M * (insertion / INSERTION_MAX_M) ** 2
    r = [factor * t for t in toward_down]
    return (cy * cp * r[0] + sy * cp * r[2]) / (cp * cp), -sy * sp * r[0] - cp * r[1] + cy * sp * r[2]


def _play_floats(motor: float, plays: tuple[float, ...], radii: list[float]) -> tuple[list[float], float]:
    """One joint's plays (rad or m) after :func:`play_update` (np.clip's values; only a zero's
    sign can differ), and the sum, in order, of ``motor - play`` over them: :func:`hysteresis_output`'s."""
    column = [motor - r if p < motor - r else motor + r if p > motor + r else p for p, r in zip(plays, radii)]
    total = motor - column[0]
    for play in column[1:]:
        total += motor - play
    return column, total


def play_update(plays: np.ndarray, q_cmd: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The outputs (n_plays, 6) of play operators (backlash elements) at ``plays`` (n_plays, 6)
    after a new command ``q_cmd`` (6,), with half-widths ``radii`` (n_plays, 6) >= 0, rad / m.

    Each play's output stays put until the command is more than its radius away, then
    is dragged along at that distance (radius zero: it follows exactly): approaching one
    command from opposite sides leaves the output on opposite sides of it.
    """
    return np.clip(plays, q_cmd - radii, q_cmd + radii)


def hysteresis_output(plays: np.ndarray, q_cmd: np.ndarray) -> np.ndarray:
    """The Prandtl-Ishlinskii joint value: the mean of the play outputs, (6,); written as
    q_cmd minus the mean lag so that zero-width plays give q_cmd bit for bit."""
    # np.mean's arithmetic (a sum, then a division by the count), without its wrapper's overhead.
    return q_cmd - np.add.reduce(q_cmd - plays, axis=0) / len(plays)


def repeatability_std(config: BiasConfig) -> np.ndarray:
    """Per-joint sd (6,) rad / m of the per-move noise.

    The five rotary joints scatter the tip: each one's share moves it by
    repeatability_m / sqrt(5) (RMS) through its lever arm, so together they scatter it by
    about repeatability_m, across the shaft (the paper's plane, nearly the image plane).
    The insertion stage gets none: what identifies the repeatability is the real rows'
    jitter in the image plane (:mod:`dvrk_gym.sim.identified`); their jitter along the view
    axis, where an insertion error would show, is the stereo depth noise's alone (the
    fidelity report's view-axis jitter, 5.2 mm real against as much simulated without
    any robot scatter), so the rows give no scatter along the shaft to model.
    """
    std = config.repeatability_m / np.sqrt(len(ROTARY_JOINTS)) / TIP_LEVER_ARMS_M
    std[INSERTION_JOINT] = 0.0
    return std


def play_radii(config: BiasConfig) -> np.ndarray:
    """(n_plays, 6) play half-widths whose loop gap equals the configured backlash."""
    gaps = np.array([config.backlash_outer_rad] * 2 + [config.backlash_insertion_m] + [config.backlash_wrist_rad] * 3)
    # A large reversal opens a gap of 2 * mean(radii); scale so it equals the gap.
    return np.outer(PLAY_FRACTIONS / PLAY_FRACTIONS.mean(), gaps / 2.0)


def _checked_joints(values: np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != (_N_JOINTS,):
        raise ValueError(f"{name} must have shape ({_N_JOINTS},), got {array.shape}")
    if all(map(math.isfinite, array.tolist())):
        return array
    for i, value in enumerate(array):
        if not np.isfinite(value):
            raise ValueError(f"{name}[{i}] ({kin.JOINT_NAMES[i]}) is {value}; expected a finite value")
    return array


class CableModel:
    """One instrument on one arm: maps joint commands (and their history) to true joints.

    Args:
        config: Error magnitudes.
        bias_seed: Seed of the instrument: the same seed draws the same offsets, DH
            table and coupling.
        instrument: This instrument instead of the one bias_seed draws (for fitting an
            instrument to data: :mod:`dvrk_gym.fidelity.identify`).

    Attributes:
        config: The BiasConfig in use.
        bias_seed: The seed the instrument was drawn from.
        instrument: The instrument drawn from bias_seed.
        true_dh: The instrument's true DH table (PSM_DH under the ``none`` preset).
    """

    def __init__(self, config: BiasConfig, bias_seed: int = 0, instrument: Instrument | None = None) -> None:
        self.config = config
        self.bias_seed = bias_seed
        self.instrument = draw_instrument(config, bias_seed) if instrument is None else instrument
        self.true_dh = self.instrument.true_dh
        self._radii = play_radii(config)
        self._noise_std = repeatability_std(config)
        # NaN = no history yet: the first command finds the cables at rest there.
        self._plays = np.full((len(PLAY_FRACTIONS), _N_JOINTS), np.nan)
        self._settle_lag = config.wrist_settle_lag
        # Where the motors stopped on the last move (what the encoders read; NaN before it).
        self._motors = np.full(_N_JOINTS, np.nan)
        # The float path's constants (peek_true_joints_floats, true_joints_floats).
        self._radii_columns, self._n_plays = self._radii.T.tolist(), len(PLAY_FRACTIONS)
        self._offsets, self._noise_std_floats = self.instrument.homing_offsets.tolist(), self._noise_std.tolist()
        self._outer_gains, self._coupling = self.instrument.outer_gains.tolist(), self.instrument.wrist_coupling.tolist()

    def measured_joints(self, q_cmd: np.ndarray) -> np.ndarray:
        """The joints (6,) rad / m the encoders read after the last move, whose command was ``q_cmd``.

        ``q_cmd`` itself (not a copy: read it, do not modify it) unless the wrist settles
        short of its commands (``BiasConfig.wrist_settle_lag`` > 0) and a move was made:
        then a copy of where the motors stopped.
        """
        if self._settle_lag == 0.0 or np.isnan(self._motors).any():
            return q_cmd
        return self._motors.copy()

    def _motor_joints(self, q_cmd: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
        """Where the motors stop for ``q_cmd`` (6,) from ``start`` (None: the last stop); nothing moves."""
        start = self._motors if start is None else start
        if self._settle_lag == 0.0 or np.isnan(start).any():
            return q_cmd
        motors = q_cmd.copy()
        motors[_WRIST_BENDING] += self._settle_lag * (start[_WRIST_BENDING] - q_cmd[_WRIST_BENDING])
        return motors

    def reset(self, q_cmd: np.ndarray) -> None:
        """Put the cables at rest at q_cmd (6,): no hysteresis gap."""
        q_cmd = _checked_joints(q_cmd, "q_cmd")
        self._plays = np.tile(q_cmd, (len(PLAY_FRACTIONS), 1))
        self._motors = q_cmd.copy()

    def true_joints(
        self, q_cmd: np.ndarray, noise_rng: np.random.Generator | None = None, *, settle_from: np.ndarray | None = None
    ) -> np.ndarray:
        """Move to a joint command and return the joints the arm really takes.

        Args:
            q_cmd: (6,) commanded (= reported) joints, rad / m.
            noise_rng: Source of this move's repeatability noise (one draw per call);
                None for a noiseless move.
            settle_from: where the motors stood as the move began (6,) rad / m (NaN: no
                history), for a point of a move sampled in several calls: the wrist settles
                short once a move; None: where the last call left them.

        Returns:
            (6,) true joint values, rad / m.
        """
        motors = self._motor_joints(_checked_joints(q_cmd, "q_cmd"), settle_from)
        self._plays, q_true = self._advance(motors)
        self._motors = motors.copy()  # the cables follow the motors
        return q_true if noise_rng is None else q_true + self.repeatability_draw(noise_rng)

    def repeatability_draw(self, noise_rng: np.random.Generator) -> np.ndarray:
        """One move's repeatability noise (6,) rad / m: the draw :meth:`true_joints` adds."""
        return noise_rng.normal(0.0, 1.0, _N_JOINTS) * self._noise_std

    def resting_true_joints(self, q_cmd: np.ndarray) -> np.ndarray:
        """:meth:`true_joints` of the last move without its noise (6,) rad / m (before any, at rest
        at ``q_cmd`` (6,)); nothing moves (:meth:`peek_true_joints` would settle the wrist again)."""
        return self.peek_true_joints(q_cmd) if np.isnan(self._motors).any() else self._advance(self._motors)[1]

    def peek_true_joints(self, q_cmd: np.ndarray) -> np.ndarray:
        """The joints (6,) rad / m that a noiseless move to ``q_cmd`` (6,) would give, without
        moving: the hysteresis state stays as it is. The same numbers as ``true_joints(q_cmd)``
        between ``get_state()`` and ``set_state()``, without copying the state."""
        return self._advance(self._motor_joints(_checked_joints(q_cmd, "q_cmd")))[1]

    def peek_true_joints_floats(self, q_cmd: list[float]) -> list[float]:
        """:meth:`peek_true_joints` for a finite command (6,) rad / m (not checked), in Python
        floats: a few ulps from it (the gravity sag solves its least squares in closed form,
        math.tanh can differ from numpy's in the last bit)."""
        if math.isnan(self._plays[0, 0]) or math.isnan(self._motors[0]):  # no history yet: the numpy path
            return self.peek_true_joints(np.array(q_cmd)).tolist()
        return self._advance_floats(q_cmd)[2]

    def true_joints_floats(self, q_cmd: list[float], noise_rng: np.random.Generator | None = None) -> list[float]:
        """:meth:`true_joints` for a finite command (6,) rad / m (not checked), in floats as
        :meth:`peek_true_joints_floats`, with the same random draw; the cables' state moves as there."""
        if math.isnan(self._plays[0, 0]) or math.isnan(self._motors[0]):
            return self.true_joints(np.array(q_cmd), noise_rng).tolist()
        motors, plays, q_true = self._advance_floats(q_cmd)
        self._plays, self._motors = np.array([column for column, _ in plays]).T.copy(), np.array(motors)
        if noise_rng is not None:
            q_true = [v + n * s for v, n, s in zip(q_true, noise_rng.normal(0.0, 1.0, _N_JOINTS).tolist(), self._noise_std_floats)]
        return q_true

    def _advance_floats(self, q_cmd: list[float]) -> tuple[list[float], list[tuple[list[float], float]], list[float]]:
        """:meth:`_advance` to :meth:`_motor_joints` in floats, history present: (the motors,
        each joint's :func:`_play_floats`, the noiseless true joints)."""
        motors = list(q_cmd)
        if self._settle_lag != 0.0:
            for i in range(_WRIST_BENDING.start, _WRIST_BENDING.stop):
                motors[i] += self._settle_lag * (float(self._motors[i]) - motors[i])
        plays = [_play_floats(m, p, r) for m, p, r in zip(motors, zip(*self._plays.tolist()), self._radii_columns)]
        q = [m - total / self._n_plays for m, (_, total) in zip(motors, plays)]
        q_true = [value + offset + error for value, offset, error in zip(q, self._offsets, self._errors_floats(q))]
        return motors, plays, q_true

    def _errors_floats(self, q: list[float]) -> list[float]:
        """The stretch and sag errors (6,) rad / m at the hysteresis output ``q``, in floats."""
        config, gains = self.config, self._outer_gains
        unloaded, scale = _OUTER_UNLOADED_FLOATS, OUTER_STRETCH_SCALE_RAD
        stretch = [gains[i] * config.outer_stretch_rad * math.tanh((q[i] - unloaded[i]) / scale) for i in (0, 1)]
        sag = _gravity_sag_floats(q, config)
        w = WRIST_STRETCH_SCALE_RAD
        wrist = [config.wrist_stretch * w * math.tanh(q[i] / w) for i in (4, 5)]
        c = self._coupling
        return [stretch[0] + sag[0], stretch[1] + sag[1], 0.0] + [c[i][0] * wrist[0] + c[i][1] * wrist[1] for i in range(3)]

    def _advance(self, q_cmd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the play outputs after a move to ``q_cmd``, the noiseless true joints there)."""
        plays = self._plays
        if np.isnan(plays).any():  # no history: the cables are at rest at the first command
            plays = np.tile(q_cmd, (len(PLAY_FRACTIONS), 1))
        plays = play_update(plays, q_cmd, self._radii)
        q = hysteresis_output(plays, q_cmd)
        error = np.zeros(_N_JOINTS)
        error[_OUTER] = outer_stretch(q, self.config, self.instrument.outer_gains) + gravity_sag(q, self.config)
        error[_WRIST] = wrist_stretch(q, self.config, self.instrument.wrist_coupling)
        return plays, q + self.instrument.homing_offsets + error

    def get_state(self) -> np.ndarray:
        """A copy of the cables' history (n_plays + 1, 6): the plays, then the motors; NaN before a move."""
        return np.concatenate((self._plays, self._motors[np.newaxis]))

    def set_state(self, state: np.ndarray) -> None:
        """Restore a state from get_state (all finite, or all NaN for 'no history')."""
        state, shape = np.array(state, dtype=float), (len(PLAY_FRACTIONS) + 1, _N_JOINTS)
        if state.shape != shape:
            raise ValueError(f"state must have shape {shape}, got {state.shape}")
        if not (np.isfinite(state).all() or np.isnan(state).all()):
            raise ValueError("state must be all finite, or all NaN (no history)")
        self._plays, self._motors = state[:-1].copy(), state[-1].copy()
