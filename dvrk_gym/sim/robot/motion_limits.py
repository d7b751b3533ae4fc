"""The tool's speed and acceleration limits (:class:`MotionLimits`), apart from the moves
that use them (:mod:`dvrk_gym.sim.robot.motion`) so that settings can name them without
loading SciPy (the env configs, and through them the registry, read these defaults).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dvrk_gym import paper
from dvrk_gym.utils.checks import check_float_fields


@dataclass(frozen=True)
class MotionLimits:
    """Speed and acceleration limits of the tool.

    Attributes:
        max_speed_m_s: top linear speed of the tool, m/s.
        max_accel_m_s2: linear acceleration and deceleration limit, m/s^2.
        max_angular_speed_rad_s: top rotational speed of the tool frame, rad/s.
        max_angular_accel_rad_s2: rotational acceleration limit, rad/s^2.
        settle_time_s: pause at the end of every move (controller settling), s.
    """

    max_speed_m_s: float = paper.MAX_TOOL_SPEED_M_S
    max_accel_m_s2: float = 0.30
    max_angular_speed_rad_s: float = math.radians(120.0)
    max_angular_accel_rad_s2: float = math.radians(600.0)
    settle_time_s: float = 0.05

    def __post_init__(self) -> None:
        bounds = {
            "max_speed_m_s": (0.0, 1.0, True),
            "max_accel_m_s2": (0.0, 100.0, True),
            "max_angular_speed_rad_s": (0.0, 100.0, True),
            "max_angular_accel_rad_s2": (0.0, 10_000.0, True),
            "settle_time_s": (0.0, 10.0, False),
        }
        check_float_fields("MotionLimits", self, bounds)
