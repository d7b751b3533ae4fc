"""Settings of Debridement-v0: the config dataclass, the timing of a pick, its action modes and
the serrated jaws' default gripper.

Like :mod:`dvrk_gym.envs.configs`, this module loads neither PyBullet nor SciPy, so that
registering the env can read its defaults (:mod:`dvrk_gym.envs`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from dvrk_gym import paper
from dvrk_gym.envs.configs import EnvConfig
from dvrk_gym.sim.robot.motion_limits import MotionLimits
from dvrk_gym.sim.table.contact import CONTACTS, DEFAULT_CONTACT
from dvrk_gym.sim.table.fragment_types import FRAGMENT_TYPES
from dvrk_gym.sim.table.gripper_config import GripperConfig
from dvrk_gym.utils.checks import check_bool, check_choice, check_float_fields, check_int_fields

ACTION_MODES = ("primitive", "delta")
PICK_ACTION_NAMES = ("bx", "by", "bz", "yaw")
DELTA_ACTION_NAMES = ("dx", "dy", "dz", "djaw")

DELTA_BOX_LOW_M = np.array([-0.035, 0.0, -0.175])
DELTA_BOX_HIGH_M = np.array([0.085, 0.085, -0.125])
"""The commanded positions delta mode may reach (the phantom and the receptacle), metres."""
SERRATED_JAW_FRICTION = 1.5
"""The jaws' friction coefficient here (PyBullet multiplies it with a fragment's: 0.68 on a
seed, 1.8 on a raisin). The Large Needle Driver's jaws are serrated. Measured with the
paper's calibrators (64 picks each): with 1.0, seeds squeezed off-centre by a millimetre
at the up to 22.5 degrees the yaw rounding leaves turn out of the jaws too often (DNN+RF
83 % with B 17 %; the paper: 92 %, B 7.5 %); with 1.5, 94 % and B 6 %."""
MAX_PICKS = 64
"""The most picks an episode may have (the paper: 8)."""


@dataclass(frozen=True)
class PickTiming:
    """How a pick moves: heights (m), speed limits and dwell times (s).

    Tuned so that over a trial the phases last as the paper's (mean frames at 25 fps: to
    seed 26.0, lower 16.1, grip 37.5, raise 24.0, to receptacle 42.1, drop and rotate
    38.5; 7.37 s a fragment) under the paper's bias. Free moves go at 6.5 cm/s (10 cm in
    1.64 s; the authors' "fast" setting took 1.49 s); the robot carries a fragment at
    3.8 cm/s, and lowers and lifts it at 3 cm/s.

    Attributes:
        approach_height_m: the free move ends this far above the target, m.
        grip_depth_m: the jaws are lowered to this far below the target (the floor,
            GRASP_TIP_CLEARANCE_M above the paper, stops them first; a command that goes on
            under the paper slides them along it, ``contact``), m. The authors' pick went
            2 mm under its target (their ``--z_offset``).
        raise_height_m: how far the jaws lift the fragment, m.
        drop_height_m: the closed jaw tip's height above the receptacle's floor when the
            jaws open (its walls are 14 mm high), m.
        travel: limits of the free move to the fragment (and the rotation after a drop).
        descend: limits of lowering and raising.
        carry: limits of the move to the receptacle with a fragment.
        grip_dwell_s: the grip phase lasts at least this long (the jaws close and the
            grasp settles), s.
        drop_fall_s: physics time the fragment gets to fall once the jaws open, s.
        drop_dwell_s: the drop-and-rotate phase lasts at least this long, s.
    """

    approach_height_m: float = 0.012
    grip_depth_m: float = 0.002
    raise_height_m: float = 0.025
    drop_height_m: float = 0.012
    travel: MotionLimits = field(default_factory=lambda: MotionLimits(max_speed_m_s=0.065, max_accel_m_s2=0.65))
    descend: MotionLimits = field(default_factory=lambda: MotionLimits(max_speed_m_s=0.03, max_accel_m_s2=0.3))
    carry: MotionLimits = field(default_factory=lambda: MotionLimits(max_speed_m_s=0.038, max_accel_m_s2=0.3))
    grip_dwell_s: float = 1.5
    drop_fall_s: float = 0.35
    drop_dwell_s: float = 1.54

    def __post_init__(self) -> None:
        heights = dict.fromkeys(("approach_height_m", "grip_depth_m", "raise_height_m", "drop_height_m"), (0.0, 0.1, False))
        dwells = dict.fromkeys(("grip_dwell_s", "drop_fall_s", "drop_dwell_s"), (0.0, 60.0, False))
        check_float_fields("PickTiming", self, {**heights, **dwells})
        for name in ("travel", "descend", "carry"):
            if not isinstance(getattr(self, name), MotionLimits):
                raise ValueError(f"PickTiming.{name} must be a MotionLimits (or its fields as a dict), got {getattr(self, name)!r}")


DEFAULT_PICK_TIMING = PickTiming()
"""The default pick timing of Debridement-v0 (tuned to the paper's phase durations)."""
_LIMITS = ("travel", "descend", "carry")
PHYSICS_STEP_S = 1.0 / 240.0
"""The physics step of every world, s (``sim.physics.client.DEFAULT_TIME_STEP_S``, which this
module does not import: it would load PyBullet for a command's ``--help``)."""
SERRATED_GRIPPER = GripperConfig(jaw_friction=SERRATED_JAW_FRICTION)
"""The default gripper of Debridement-v0: GripperConfig with the serrated jaws' friction."""


@dataclass(frozen=True)
class DebridementConfig(EnvConfig):
    """Settings of Debridement-v0.

    Attributes:
        fragment: "pumpkin_seed" or "raisin".
        action_mode: "primitive" (one pick per step) or "delta" (increments at 10 Hz).
        max_picks: picks per episode in primitive mode (the paper: 8).
        max_steps: steps per episode in delta mode.
        remove_failed: after a failed pick the fragment is taken away, so each fragment
            gets one attempt (the paper's protocol); False leaves it for another try.
        timing: heights, speeds and dwell times of a pick.
        gripper: grip force, jaw speed, jaw friction (SERRATED_JAW_FRICTION) and contact
            thresholds.
        control_period_s: delta mode's time per step, s.
        max_delta_m: largest position increment per delta step, per axis, m.
        max_delta_jaw_rad: largest jaw increment per delta step, rad.
        delta_yaw_rad: the tool's yaw in delta mode (pitch and roll by the paper's rule), rad.
        contact: how the paper takes jaws sent under the floor that stops them
            (:mod:`dvrk_gym.sim.table.contact`, as GridTouch-v0's ``contact``): "compliant"
            (they slide along it by the identified slide per depth) or "rigid" (they stall
            where they are).
    """

    fragment: str = "pumpkin_seed"
    action_mode: str = "primitive"
    max_picks: int = paper.FRAGMENTS_PER_TRIAL
    max_steps: int = 600
    remove_failed: bool = True
    timing: PickTiming = DEFAULT_PICK_TIMING
    gripper: GripperConfig = SERRATED_GRIPPER
    control_period_s: float = 0.1
    max_delta_m: float = 0.005
    max_delta_jaw_rad: float = 0.25
    delta_yaw_rad: float = 0.0
    contact: str = DEFAULT_CONTACT

    def __post_init__(self) -> None:
        super().__post_init__()
        # Settings read back from JSON (a saved agent's, say) hold the nested configs as dicts;
        # a dict of some fields changes those of the env's defaults (not of the classes' own).
        try:
            if isinstance(self.timing, dict):
                limits = {
                    k: dataclasses.replace(getattr(DEFAULT_PICK_TIMING, k), **v) if isinstance(v, dict) and k in _LIMITS else v
                    for k, v in self.timing.items()
                }
                object.__setattr__(self, "timing", dataclasses.replace(DEFAULT_PICK_TIMING, **limits))
            if isinstance(self.gripper, dict):
                object.__setattr__(self, "gripper", dataclasses.replace(SERRATED_GRIPPER, **self.gripper))
        except TypeError as error:  # a misspelt field
            raise ValueError(f"bad timing or gripper settings: {error}") from error
        if not isinstance(self.timing, PickTiming) or not isinstance(self.gripper, GripperConfig):
            raise ValueError(
                "timing must be a PickTiming and gripper a GripperConfig (or their fields as dicts), "
                f"got {type(self.timing).__name__} and {type(self.gripper).__name__}"
            )
        check_choice("fragment", self.fragment, sorted(FRAGMENT_TYPES))
        check_choice("action_mode", self.action_mode, ACTION_MODES)
        check_choice("contact", self.contact, tuple(CONTACTS))
        check_int_fields("DebridementConfig", self, {"max_picks": (1, MAX_PICKS), "max_steps": (1, 1_000_000)})
        check_bool("remove_failed", self.remove_failed)
        bounds = {
            "control_period_s": (0.0, 10.0, True),
            "max_delta_m": (0.0, 0.05, True),
            "max_delta_jaw_rad": (0.0, math.pi, True),
            "delta_yaw_rad": (-math.pi / 2, math.pi / 2, False),
        }
        check_float_fields("DebridementConfig", self, bounds, units={"control_period_s": "s", "max_delta_m": "m"})
        steps = self.control_period_s / PHYSICS_STEP_S
        if round(steps) < 1 or abs(steps - round(steps)) > 1e-6:  # a move lasts whole physics steps: 0.01 s took 0.0125
            raise ValueError(
                f"control_period_s = {self.control_period_s} s is not a whole number of physics steps of {PHYSICS_STEP_S:.6g} s "
                f"(1/240 s); use e.g. {max(1, round(steps)) * PHYSICS_STEP_S:.6g}"
            )
