"""How the jaws squeeze and hold (:class:`GripperConfig`): grip force, jaw speed, friction
and the thresholds of grasping and piercing.

Apart from the :class:`~dvrk_gym.sim.table.grasp.Gripper` that uses it, so that settings
can name it without loading PyBullet; :mod:`dvrk_gym.sim.table.grasp` says how each
setting acts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dvrk_gym.utils.checks import check_float_fields, check_int_fields


@dataclass(frozen=True)
class GripperConfig:
    """How the jaws squeeze and hold.

    Attributes:
        grip_force_n: the force each jaw closes with on what it holds, N.
        jaw_speed_rad_s: how fast the opening angle changes, rad/s.
        stop_depth_m: a closing jaw stops once it is this far into something that does
            not give way, m.
        jaw_friction: the jaws' friction coefficient (PyBullet multiplies it with the
            fragment's, so 1 leaves the fragment's own).
        grasp_steps: steps in a row both jaws must touch a fragment antipodally before
            it is held.
        pierce_tip_zone_m: contacts this close to a jaw's end count as its tip, m.
        pierce_max_angle_rad: largest angle between the jaw and the inward surface normal
            for the tip to press end-on.
        pierce_tear_m: a pierce tears when the tip and its hole are this far apart, m.
        max_free_speed_m_s: a fragment not held is slowed to this speed (a guard: the
            solver can shoot a squeezed 0.1 g body out at metres per second).
    """

    grip_force_n: float = 1.0
    jaw_speed_rad_s: float = math.radians(150.0)
    stop_depth_m: float = 5.0e-5
    jaw_friction: float = 1.0
    grasp_steps: int = 3
    pierce_tip_zone_m: float = 1.0e-3
    pierce_max_angle_rad: float = math.radians(35.0)
    pierce_tear_m: float = 1.0e-3
    max_free_speed_m_s: float = 0.2

    def __post_init__(self) -> None:
        bounds = {
            "grip_force_n": (0.0, 100.0, True),
            "jaw_speed_rad_s": (0.0, 100.0, True),
            "stop_depth_m": (0.0, 0.01, True),
            "jaw_friction": (0.0, 10.0, False),
            "pierce_tip_zone_m": (0.0, 0.01, False),
            "pierce_max_angle_rad": (0.0, math.pi / 2, False),
            "pierce_tear_m": (0.0, 0.01, True),
            "max_free_speed_m_s": (0.0, 100.0, True),
        }
        check_float_fields("GripperConfig", self, bounds)
        check_int_fields("GripperConfig", self, {"grasp_steps": (1, 10_000)})
