"""Straight Cartesian moves with speed and acceleration limits, and the simulated clock.

The real dVRK moves its tool at up to about 6 cm/s (the authors' code: a 10 cm move at
"fast" took 1.49 s). A move here is a straight line in position and a slerp in
orientation, both following one trapezoidal speed profile, so a move's duration is the
time the real robot would need. That time is kept by a :class:`SimClock`, separate from
wall time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from dvrk_gym.sim.robot.motion_limits import MotionLimits


def trapezoid_timing(distance: float, max_speed: float, max_accel: float) -> tuple[float, float]:
    """Duration and ramp time to travel ``distance`` from rest to rest.

    Args:
        distance: path length (m, or rad for rotations).
        max_speed: speed limit (per second), > 0.
        max_accel: acceleration limit (per second squared), > 0.

    Returns:
        (duration, ramp) in seconds; the profile is triangular (ramp = duration / 2) when
        the top speed is never reached.
    """
    distance = abs(float(distance))
    if distance * max_accel <= max_speed**2:
        ramp = math.sqrt(distance / max_accel)
        return 2.0 * ramp, ramp
    return distance / max_speed + max_speed / max_accel, max_speed / max_accel


_EYE3 = np.eye(3)
_ANGLE_BOUND_MARGIN_RAD = 2e-5
"""Added to :func:`rotation_angle_bound`: more than the round-off of the bound and of scipy's
angle, and than how far either moves for a matrix off orthonormal by up to 1e-6 (what
:mod:`~dvrk_gym.sim.robot.ik` accepts in a pose; measured: under 1e-5 rad). A larger bound only
sends more plans to scipy (a plan of 2e-5 rad takes 3 ms)."""


_TIGHT_BOUND_MAX_SINE = math.sin(1.5)
"""Up to this sin(angle / 2) (angles to 3 rad) the bound is the angle itself: the arcsine's
slope, at most 1 / cos(1.5) = 14, keeps its round-off near 1e-14 rad."""


def rotation_angle_bound(rotation: np.ndarray) -> float:
    """An upper bound, rad, on the angle of a rotation matrix (3, 3), without scipy.

    ``|R - I|_F = 2 sqrt(2) sin(angle / 2)``: up to 3 rad the bound is the angle that gives,
    ``2 asin(|R - I|_F / (2 sqrt(2)))``; beyond, where the arcsine is steep, it is
    ``pi |R - I|_F / (2 sqrt(2))`` (``sin(x / 2) >= x / pi`` on [0, pi]; exact at pi). Plus
    a margin for round-off, of this formula and of scipy's angle.
    """
    half_chord = math.sqrt(float(np.square(rotation - _EYE3).sum())) / (2.0 * math.sqrt(2.0))
    if half_chord <= _TIGHT_BOUND_MAX_SINE:
        return 2.0 * math.asin(half_chord) + _ANGLE_BOUND_MARGIN_RAD
    return math.pi * half_chord + _ANGLE_BOUND_MARGIN_RAD


def trapezoid_progress(t: float, duration: float, ramp: float) -> float:
    """Fraction in [0, 1] of the path covered ``t`` seconds into a trapezoidal profile.

    Args:
        t: time since the start of the move, s.
        duration: total duration, s.
        ramp: acceleration (and deceleration) time, s, at most ``duration / 2``.
    """
    if duration <= 0.0:
        return 1.0
    t = min(max(t, 0.0), duration)
    ramp = min(max(ramp, 1e-12), duration / 2)
    peak = 1.0 / (duration - ramp)  # normalised top speed: the profile's area is 1
    if t < ramp:
        return 0.5 * peak * t * t / ramp
    if t <= duration - ramp:
        return peak * (t - 0.5 * ramp)
    remaining = duration - t
    return 1.0 - 0.5 * peak * remaining * remaining / ramp


@dataclass(frozen=True)
class CartesianMove:
    """A straight move of the tool frame from ``start`` to ``end`` (4x4 poses, metres).

    Attributes:
        start: the initial pose, base frame.
        end: the final pose, base frame.
        duration_s: how long the move takes, seconds (excluding settling).
        ramp_s: its acceleration (and deceleration) time, seconds.
    """

    start: np.ndarray
    end: np.ndarray
    duration_s: float
    ramp_s: float

    @classmethod
    def plan(cls, start: np.ndarray, end: np.ndarray, limits: MotionLimits) -> CartesianMove:
        """Plan a move whose duration respects both the linear and the angular limits (ValueError: ``limits`` is no MotionLimits)."""
        if not isinstance(limits, MotionLimits):
            raise ValueError(f"limits must be a MotionLimits, got {limits!r}")
        offset = end[:3, 3] - start[:3, 3]
        distance = math.sqrt(offset.dot(offset))  # np.linalg.norm's own formula, without its checks
        linear = trapezoid_timing(distance, limits.max_speed_m_s, limits.max_accel_m_s2)
        relative = start[:3, :3].T @ end[:3, :3]
        # The slower of the two sets the profile; the other follows the same fraction, so
        # position and orientation arrive together and neither exceeds its limits. The
        # rotation's angle (scipy, slow) is needed only when a bound on it could be slower.
        bound = trapezoid_timing(rotation_angle_bound(relative), limits.max_angular_speed_rad_s, limits.max_angular_accel_rad_s2)
        if bound[0] < linear[0]:
            duration, ramp = linear
        else:
            angle = float(Rotation.from_matrix(relative).magnitude())
            angular = trapezoid_timing(angle, limits.max_angular_speed_rad_s, limits.max_angular_accel_rad_s2)
            duration, ramp = max(linear, angular)
        return cls(np.array(start, dtype=float), np.array(end, dtype=float), duration, ramp)

    def pose_at(self, t: float) -> np.ndarray:
        """The commanded pose ``t`` seconds after the start of the move."""
        s = trapezoid_progress(t, self.duration_s, self.ramp_s)
        pose = np.eye(4)
        pose[:3, 3] = (1.0 - s) * self.start[:3, 3] + s * self.end[:3, 3]
        rotations = Rotation.from_matrix(np.stack([self.start[:3, :3], self.end[:3, :3]]))
        pose[:3, :3] = Slerp([0.0, 1.0], rotations)(s).as_matrix()
        return pose

    def waypoints(self, dt_s: float) -> list[np.ndarray]:
        """Poses every ``dt_s`` seconds along the move, ending exactly at ``end``."""
        n = max(1, math.ceil(self.duration_s / dt_s))
        return [self.pose_at(self.duration_s * (i + 1) / n) for i in range(n)]


class SimClock:
    """Simulated time: the seconds the real robot would have needed, not wall time."""

    def __init__(self) -> None:
        self._time_s = 0.0

    @property
    def time_s(self) -> float:
        """Seconds elapsed since the last reset."""
        return self._time_s

    def advance(self, seconds: float) -> None:
        """Move the clock forward by ``seconds`` (>= 0)."""
        if not (math.isfinite(seconds) and seconds >= 0.0):
            raise ValueError(f"the clock only moves forward by a finite amount, got {seconds}")
        self._time_s += float(seconds)

    def reset(self) -> None:
        """Set the clock back to zero."""
        self._time_s = 0.0
