"""Settings of Debridement-v0: the config dataclass, its action modes and the serrated jaws' default gripper."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper
from dvrk_gym.envs.base import EnvConfig
from dvrk_gym.envs.picks import PickTiming
from dvrk_gym.sim.robot.motion import MotionLimits
from dvrk_gym.sim.table.fragments import FRAGMENT_TYPES
from dvrk_gym.sim.table.grasp import GripperConfig
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
DEFAULT_PICK_TIMING = PickTiming()
"""The default pick timing of Debridement-v0 (tuned to the paper's phase durations)."""
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

    def __post_init__(self) -> None:
        super().__post_init__()
        # Settings read back from JSON (a saved agent's, say) hold the nested configs as dicts.
        try:
            if isinstance(self.timing, dict):
                limits = {k: MotionLimits(**v) if isinstance(v, dict) else v for k, v in self.timing.items()}
                object.__setattr__(self, "timing", PickTiming(**limits))  # type: ignore[arg-type]  # checked below
            if isinstance(self.gripper, dict):
                object.__setattr__(self, "gripper", GripperConfig(**self.gripper))
        except TypeError as error:  # a misspelt field
            raise ValueError(f"bad timing or gripper settings: {error}") from error
        if not isinstance(self.timing, PickTiming) or not isinstance(self.gripper, GripperConfig):
            raise ValueError(
                "timing must be a PickTiming and gripper a GripperConfig (or their fields as dicts), "
                f"got {type(self.timing).__name__} and {type(self.gripper).__name__}"
            )
        check_choice("fragment", self.fragment, sorted(FRAGMENT_TYPES))
        check_choice("action_mode", self.action_mode, ACTION_MODES)
        check_int_fields("DebridementConfig", self, {"max_picks": (1, MAX_PICKS), "max_steps": (1, 1_000_000)})
        check_bool("remove_failed", self.remove_failed)
        bounds = {
            "control_period_s": (0.0, 10.0, True),
            "max_delta_m": (0.0, 0.05, True),
            "max_delta_jaw_rad": (0.0, math.pi, True),
            "delta_yaw_rad": (-math.pi / 2, math.pi / 2, False),
        }
        check_float_fields("DebridementConfig", self, bounds, units={"control_period_s": "s", "max_delta_m": "m"})
