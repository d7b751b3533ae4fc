"""How far the dVRK misses, and which instrument it is: the bias's magnitudes and draws.

The dVRK controller turns a commanded tool pose into joint commands with the *nominal*
inverse kinematics, and its encoders report where the motors went (the commands, but for a
wrist that settles short of them); cables between the motors and the joints, and an
instrument machined to a tolerance, put the tool elsewhere. This
module holds the magnitudes of those errors (:class:`BiasConfig`, the presets
``none`` / ``paper`` / ``severe`` and why the ``paper`` ones) and the draws that make one
instrument (:func:`draw_instrument`: homing offsets, true DH table, cable gains).
:class:`dvrk_gym.sim.robot.cables.CableModel` applies them move by move;
:mod:`dvrk_gym.sim.robot.bias_statistics` measures the result over the paper's workspace.
Joint vectors follow :data:`dvrk_gym.sim.robot.kinematics.JOINT_NAMES` (rad, insertion in m).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from dvrk_gym.sim import identified
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.utils.checks import check_bool, check_float

__all__ = [
    "BiasConfig",
    "BIAS_PRESETS",
    "resolve_bias",
    "Instrument",
    "draw_instrument",
    "identified_instrument",
    "homing_offsets",
    "perturbed_dh",
    "wrist_coupling",
    "outer_stretch_gains",
    "NOMINAL_WRIST_COUPLING",
    "INSTRUMENT_SPREAD",
    "MAX_MAGNITUDE",
]

_N_JOINTS = 6
_DEG = np.pi / 180.0


def _frozen(values: object) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False  # module constants are shared by every model
    return array


# Nominal coupling of wrist-cable stretch (rows: roll, wrist pitch, wrist yaw error;
# columns: wrist pitch, wrist yaw stretch). The yaw cables run over the pitch pulleys, so
# pitch load stretches them too (as in the dVRK's actuator-to-joint coupling for this
# tool); both cable pairs run down the shaft and twist it a little when loaded.
NOMINAL_WRIST_COUPLING = _frozen([[0.15, 0.15], [1.0, 0.0], [0.5, 1.0]])
# Cable routing, pretension and wear differ between instruments: each stretch gain and
# coupling entry of one instrument is its nominal value times ~ N(1, this sd).
INSTRUMENT_SPREAD = 0.1


_NOT_MAGNITUDES = ("around_identified", "wrist_settle_lag")
MAX_MAGNITUDE = {"rad": 1.0, "m": 0.05, "": 1.0}
"""The largest magnitude a :class:`BiasConfig` takes, by the unit its field's name ends
in (rad, m, or none: the wrist's stretch): ten times the ``paper`` instrument's largest
term of each kind is well inside (its wrist backlash, 0.060 rad; its repeatability, 1 mm;
its wrist stretch, 0.09), and beyond them the tool leaves the endoscope's view."""


@dataclass(frozen=True)
class BiasConfig:
    """Magnitudes of the error terms (SI units). All zero: the robot goes where told.

    Attributes:
        homing_offset_rad: sd of the per-instrument constant offset of each revolute
            joint (homing from potentiometers), rad.
        homing_offset_m: sd of the constant insertion offset, m.
        tool_length_m: sd of the error of the shaft length (0.4162 m) and wrist offset
            (0.0091 m) of the instrument, m.
        tool_twist_rad: sd of the error of the twists of DH rows 4-6 (roll, wrist pitch,
            wrist yaw axes), rad.
        outer_stretch_rad: saturated stretch error of the outer yaw / pitch cables, rad
            (slope at zero: outer_stretch_rad / cables.OUTER_STRETCH_SCALE_RAD).
        wrist_stretch: small-deflection compliance of the wrist cables, rad of joint
            error per rad of wrist deflection (dimensionless).
        sag_m: tip sag of a horizontal shaft at full insertion (0.24 m) under gravity, m.
        backlash_outer_rad: hysteresis gap of outer yaw and pitch between opposite
            approaches, rad.
        backlash_insertion_m: hysteresis gap of the insertion, m.
        backlash_wrist_rad: hysteresis gap of roll, wrist pitch and wrist yaw, rad.
        repeatability_m: RMS tip scatter of repeated moves to one command, across the shaft, m.
        around_identified: draw instruments around the one identified from the real rows
            (:mod:`dvrk_gym.sim.identified`): bias_seed 0 is that instrument, bias_seed k
            >= 1 one drawn around it with the identification's spread
            (:func:`identified_instrument`). The homing and tool sds above are then unused.
            False: around the nominal instrument, with those sds.
        wrist_settle_lag: the fraction in [0, 1) of each commanded wrist-pitch and
            wrist-yaw step that their motors have not made when a move ends (a servo
            stopped short of its command): the motors go to ``q_cmd + wrist_settle_lag *
            (previous motors - q_cmd)``, the cables follow the motors, and the encoders
            report the motors, so the reported pose lags the command. 0: the motors reach
            the command. ``paper`` and ``severe``: the lag matched to the real rows
            (:data:`dvrk_gym.sim.identified.WRIST_SETTLE_LAG`, 0.19); a fraction, not a
            magnitude, so ``scaled`` leaves it.
    """

    homing_offset_rad: float = 0.0
    homing_offset_m: float = 0.0
    tool_length_m: float = 0.0
    tool_twist_rad: float = 0.0
    outer_stretch_rad: float = 0.0
    wrist_stretch: float = 0.0
    sag_m: float = 0.0
    backlash_outer_rad: float = 0.0
    backlash_insertion_m: float = 0.0
    backlash_wrist_rad: float = 0.0
    repeatability_m: float = 0.0
    around_identified: bool = False
    wrist_settle_lag: float = 0.0

    def __post_init__(self) -> None:
        """Check every field (a real number in its range; ``around_identified`` a bool) and
        keep the numbers as floats.

        Raises:
            ValueError: naming the field and its range.
        """
        for name in self.magnitude_names():
            unit = name.rsplit("_", 1)[-1] if name.endswith(("_rad", "_m")) else ""
            value = check_float(f"BiasConfig.{name}", getattr(self, name), low=0.0, high=MAX_MAGNITUDE[unit], unit=unit)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "around_identified", check_bool("BiasConfig.around_identified", self.around_identified))
        lag = check_float("BiasConfig.wrist_settle_lag", self.wrist_settle_lag, low=0.0, high=1.0)
        if lag >= 1.0:
            raise ValueError(f"BiasConfig.wrist_settle_lag = {lag}; expected a value in [0, 1)")
        object.__setattr__(self, "wrist_settle_lag", lag)

    @classmethod
    def magnitude_names(cls) -> tuple[str, ...]:
        """The names of the fields that are magnitudes (all but ``around_identified`` and ``wrist_settle_lag``)."""
        return tuple(f.name for f in dataclasses.fields(cls) if f.name not in _NOT_MAGNITUDES)

    def scaled(self, factor: float) -> BiasConfig:
        """This configuration with every magnitude multiplied by factor (>= 0); ValueError
        for one that takes a magnitude past ``MAX_MAGNITUDE`` (the ``paper`` instrument's
        wrist stretch passes at 11 times). With ``around_identified``, the instrument's homing
        offsets are not magnitudes and stay: ``paper`` scaled by 0 still reports its joints
        off by them (``none`` is the robot that goes where told)."""
        return dataclasses.replace(self, **{name: getattr(self, name) * factor for name in self.magnitude_names()})


# The `paper` magnitudes are the instrument identified from the authors' real Phase I rows
# (dvrk_gym.sim.identified, where each value's fit, held-out residual and command are
# given): outer stretch about 0.37 deg (not the 2.6 deg once tuned to the paper's table),
# wrist stretch 0.09, a wrist backlash of 3.4 deg and no outer one, and a repeatability of
# about 1.0 mm across the shaft (what the rows leave unexplained from one row to the next),
# and wrist motors that stop 0.19 of each step short (the reported pose's lag, matched
# to how often consecutive real rows report the same position). Gravity sag and the
# insertion's backlash are not separable from the camera pose and the other terms in those
# rows, so they are left out (0) rather than guessed.
_PAPER = BiasConfig(
    outer_stretch_rad=identified.OUTER_STRETCH_MAGNITUDE_RAD,
    wrist_stretch=abs(identified.INSTRUMENT.wrist_stretch),
    backlash_outer_rad=identified.INSTRUMENT.backlash_outer_rad,
    backlash_wrist_rad=identified.INSTRUMENT.backlash_wrist_rad,
    repeatability_m=identified.INSTRUMENT.repeatability_m,
    around_identified=True,
    wrist_settle_lag=identified.WRIST_SETTLE_LAG,
)
BIAS_PRESETS: dict[str, BiasConfig] = {
    "none": BiasConfig(),
    "paper": _PAPER,
    "severe": _PAPER.scaled(2.0),
}
"""``none``: the robot goes where told. ``paper``: the identified instrument (bias_seed 0)
and instruments drawn around it (bias_seed >= 1). ``severe``: ``paper`` with every cable
magnitude doubled (the settle lag, a fraction, and the instrument's homing offsets, the
encoders' zeros, kept)."""


def resolve_bias(bias: str | BiasConfig) -> BiasConfig:
    """A BiasConfig from a preset name or a BiasConfig (returned unchanged).

    Raises:
        ValueError: bias is a string that names no preset.
        TypeError: bias is neither a string nor a BiasConfig.
    """
    if isinstance(bias, BiasConfig):
        return bias
    if isinstance(bias, str):
        if bias not in BIAS_PRESETS:
            raise ValueError(f"unknown bias preset {bias!r}; expected one of {sorted(BIAS_PRESETS)}")
        return BIAS_PRESETS[bias]
    raise TypeError(f"bias must be a preset name or a BiasConfig, got {type(bias).__name__}")


# --- one instrument ----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Instrument:
    """What one instrument on one arm keeps from move to move (read-only arrays).

    Attributes:
        homing_offsets: (6,) constant joint offsets, rad / m.
        true_dh: The instrument's true DH table (PSM_DH under the ``none`` preset).
        wrist_coupling: (3, 2) coupling of wrist-pitch / wrist-yaw cable stretch (columns)
            into roll / wrist-pitch / wrist-yaw errors (rows), dimensionless.
        outer_gains: (2,) factors near 1 on the outer yaw / pitch cable stretch.
    """

    homing_offsets: np.ndarray
    true_dh: tuple[kin.DHRow, ...]
    wrist_coupling: np.ndarray
    outer_gains: np.ndarray


def draw_instrument(config: BiasConfig, bias_seed: int) -> Instrument:
    """The instrument of seed bias_seed: the same seed draws the same instrument.

    Around the nominal instrument, the draws come from one generator in a fixed order:
    homing offsets, DH table, wrist coupling, outer gains. Around the identified one, see
    :func:`identified_instrument`.
    """
    if config.around_identified:
        return identified_instrument(config, bias_seed)
    rng = np.random.default_rng(bias_seed)
    offsets = homing_offsets(config, rng)
    true_dh = perturbed_dh(config, rng)
    coupling = wrist_coupling(rng)
    gains = outer_stretch_gains(rng)
    return Instrument(_frozen(offsets), true_dh, _frozen(coupling), _frozen(gains))


def homing_offsets(config: BiasConfig, rng: np.random.Generator) -> np.ndarray:
    """Constant joint offsets of one instrument, (6,) rad / m.

    The dVRK homes each joint from a potentiometer reading, which is good to about a
    degree; every joint angle afterwards carries that offset.
    """
    scale = np.full(_N_JOINTS, config.homing_offset_rad)
    scale[2] = config.homing_offset_m
    return rng.normal(0.0, 1.0, _N_JOINTS) * scale


def perturbed_dh(config: BiasConfig, rng: np.random.Generator) -> tuple[kin.DHRow, ...]:
    """The instrument's true DH table: PSM_DH with its tool lengths and twists perturbed.

    The shaft length (row 4, d = 0.4162 m), the wrist offset (row 6, a = 0.0091 m) and the
    twists of the roll, wrist-pitch and wrist-yaw axes (rows 4-6) come from machining and
    assembly of each instrument, good to a few tenths of a millimetre and degree.
    """
    length_errors = rng.normal(0.0, config.tool_length_m, 2)
    twist_errors = rng.normal(0.0, config.tool_twist_rad, 3)
    rows = list(kin.PSM_DH)
    rows[3] = dataclasses.replace(rows[3], d_offset_m=rows[3].d_offset_m + length_errors[0])
    rows[5] = dataclasses.replace(rows[5], a_m=rows[5].a_m + length_errors[1])
    for i, twist_error in zip(range(3, 6), twist_errors):
        rows[i] = dataclasses.replace(rows[i], alpha_rad=rows[i].alpha_rad + twist_error)
    return tuple(rows)


def wrist_coupling(rng: np.random.Generator) -> np.ndarray:
    """One instrument's (3, 2) coupling of wrist-cable stretch into wrist-joint errors.

    NOMINAL_WRIST_COUPLING with each entry scaled by a factor ~ N(1, INSTRUMENT_SPREAD).
    """
    factors = 1.0 + INSTRUMENT_SPREAD * rng.normal(0.0, 1.0, NOMINAL_WRIST_COUPLING.shape)
    return NOMINAL_WRIST_COUPLING * factors


def outer_stretch_gains(rng: np.random.Generator) -> np.ndarray:
    """One instrument's (2,) factors on the outer yaw / pitch stretch, each ~ N(1, INSTRUMENT_SPREAD)."""
    return 1.0 + INSTRUMENT_SPREAD * rng.normal(0.0, 1.0, 2)


def identified_instrument(config: BiasConfig, bias_seed: int) -> Instrument:
    """The identified instrument (bias_seed 0), or one drawn around it (bias_seed >= 1).

    The identified values (:data:`dvrk_gym.sim.identified.INSTRUMENT`) are its homing
    offsets, its signed outer-stretch amplitudes (as gains on config.outer_stretch_rad) and
    its signed wrist stretch (as the sign and size of the coupling on config.wrist_stretch);
    its DH table is the nominal one. A config scaled from ``paper`` scales the two stretches with
    it; the homing offsets are the encoders' zeros, not a cable magnitude, so no config scales
    them (``config`` is not read for them). Instrument k >= 1 adds to each identified value a
    normal draw with that value's sd over the identification's block bootstrap
    (:data:`dvrk_gym.sim.identified.INSTRUMENT_SD`), in this order: homing offsets (6),
    outer amplitudes (2), wrist stretch (1): an instrument the real rows could not tell
    from the identified one.
    """
    values, sd = identified.INSTRUMENT, identified.INSTRUMENT_SD
    offsets = np.array(values.homing_offsets)
    amplitudes = np.array(values.outer_stretch_rad)
    wrist = values.wrist_stretch
    if bias_seed != 0:
        rng = np.random.default_rng(bias_seed)
        offsets = offsets + rng.normal(0.0, 1.0, _N_JOINTS) * np.array(sd.homing_offsets)
        amplitudes = amplitudes + rng.normal(0.0, 1.0, 2) * np.array(sd.outer_stretch_rad)
        wrist = wrist + rng.normal() * sd.wrist_stretch
    # Relative to the identified magnitudes, so that a scaled config scales the stretch.
    gains = amplitudes / identified.OUTER_STRETCH_MAGNITUDE_RAD
    coupling = NOMINAL_WRIST_COUPLING * (wrist / abs(values.wrist_stretch))
    return Instrument(_frozen(offsets), kin.PSM_DH, _frozen(coupling), _frozen(gains))
