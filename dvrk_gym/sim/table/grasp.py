"""How the jaws act on fragments: pushing, grasping (with a squeeze), piercing.

:class:`Gripper` drives the arm and the jaws through physics steps and decides what they
hold; the contact tests and the constraints it holds with are in
:mod:`dvrk_gym.sim.table.holding`.

The arm and the jaws are moved kinematically, one physics step at a time: every step
each joint is set where it should be, with the velocity it moves at (so contacts see a
moving jaw), and a strong velocity motor keeps that velocity through the step.

A fragment moves only through contact with the jaws:

* **Pushing** is plain contact physics. The jaws close together (the grip is the
  differential of two cable-driven jaws whose common mode, the wrist yaw, holds still),
  so the jaw that reaches a fragment first pushes it towards the other; a jaw stops when
  it presses into something that does not give (the paper, or a fragment pinned
  against it) by :attr:`GripperConfig.stop_depth_m`. A jaw landing on a seed shoves it;
  jaws closing near a seed's end squeeze it out.
* **Grasp**: when both jaws touch the same fragment and their squeeze is antipodal (the
  line between the contacts lies inside both friction cones, in the fragment's plane)
  for :attr:`GripperConfig.grasp_steps` steps, the fragment is held by a fixed
  constraint to the wrist (the jaws' common pivot) that bears at most friction x the
  two grip forces. The jaws then squeeze on by the fragment's compression,
  ``grip_force / stiffness`` (collisions between the jaws and a held fragment are off,
  so the solver does not fight the overlap), and the fragment stays held only while both
  jaws press on it: as soon as either opens back past where it first touched, the
  constraint goes and the fragment falls. A squeeze that is not antipodal never holds:
  the seed slides out or is left behind (failure mode B).
* **Piercing** (raisins): a jaw tip that presses end-on into a pierceable fragment that
  cannot give way, with the fragment's pierce force (its stiffness times how far the
  tip is in), goes in and holds it by a point constraint at the tip, which bears at
  most ``pierce_hold_n`` and does not let go when the jaws open (failure mode C). It
  tears off when something holds the fragment back harder than that.

Why not friction alone: measured here, neither torque-limited jaw motors nor kinematic
jaws lift a 0.1 g fragment by friction in PyBullet. The solver transmits only about 0.1 N
through so light a body whatever the motor torque (0.0013 N m applied of 0.02 N m
asked), so the jaws creep through it or shoot it away, and soft contacts squeezed
between a jaw and the paper sink into the paper.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.body import PSMBody
from dvrk_gym.sim.table import holding
from dvrk_gym.sim.table.fragments import Fragment
from dvrk_gym.sim.table.gripper_config import GripperConfig
from dvrk_gym.sim.table.holding import JAW_LINKS, Hold, Touch
from dvrk_gym.utils.checks import check_float

GRASP_TIP_CLEARANCE_M = 0.0007
"""Where to stop the closed jaw tip above the paper before closing, m. With the paper's
roll (-170 to -165 deg) the jaws close in a plane tilted about 12 deg, so while closing the
lower jaw dips about 0.5 mm below the closed tip; 0.7 mm clears the paper and still
pinches a 2.4 mm seed below its middle."""

ARM_JOINTS = 6
_STILL_RAD = 1e-7
_INTO_COS = 0.3
"""A contact blocks a closing jaw only if the jaw moves into it within about 73 degrees of its normal."""


class Gripper:
    """Drives a PSMBody's arm and jaws through physics steps and decides what they hold.

    Args:
        physics: the world.
        robot: the tool body (its joints are driven here, in its own true joint space).
        fragments: the fragments the jaws can grasp or pierce.
        config: grip force, speeds and thresholds.
    """

    def __init__(self, physics: Physics, robot: PSMBody, fragments: Sequence[Fragment] = (), config: GripperConfig | None = None) -> None:
        self.physics = physics
        self.robot = robot
        self.config = config or GripperConfig()
        self.fragments: dict[int, Fragment] = {f.body_id: f for f in fragments}
        self._by_name = {f.name: f for f in fragments}
        self.holds: dict[str, Hold] = {}
        self._streak: dict[str, int] = {}
        self._first_touch: dict[str, np.ndarray] = {}
        self.q = np.array(robot.joints, dtype=float)
        self.half_angles = np.full(2, max(robot.jaw_angle, 0.0) / 2)
        self.jaw_target = float(robot.jaw_angle)
        self._touches: list[dict[int, Touch]] = [{}, {}]
        for link in JAW_LINKS:
            physics.client.changeDynamics(robot.body_id, link, lateralFriction=self.config.jaw_friction)

    # ------------------------------------------------------------------ queries
    @property
    def jaw_angle(self) -> float:
        """The jaws' actual opening angle, radians (less than commanded when blocked)."""
        return float(self.half_angles.sum())

    def held(self) -> dict[str, str]:
        """Names of the fragments held now, each with "grasp" or "pierce"."""
        return {name: hold.mode for name, hold in self.holds.items()}

    def indentation(self, name: str) -> float:
        """How far the jaws have closed into a grasped fragment, summed over both, m."""
        hold = self.holds.get(name)
        if hold is None or hold.mode != "grasp":
            return 0.0
        return float(np.maximum(hold.contact_half_angles - self.half_angles, 0.0) @ hold.levers_m)

    # ------------------------------------------------------------------ commands
    def place(self, q: np.ndarray, jaw_angle_rad: float | None = None) -> None:
        """Teleport the tool to joints ``q`` without stepping physics (free-space moves).

        Held fragments go along, keeping their pose relative to what holds them. The jaw
        opening is left alone while something is grasped.
        """
        if jaw_angle_rad is not None:
            self.jaw_target = float(jaw_angle_rad)
            if not any(h.mode == "grasp" for h in self.holds.values()):
                self.half_angles[:] = max(self.jaw_target, 0.0) / 2
        carried = {name: self._pose_in_link(name) for name in self.holds}
        self.q = np.array(q, dtype=float)
        self._drive(np.zeros(ARM_JOINTS), np.zeros(2))
        for name, relative in carried.items():
            self._restore_pose_in_link(name, relative)

    def command_jaw(self, jaw_angle_rad: float) -> None:
        """Set the opening the jaws move towards (radians; <= 0 closes fully).

        Raises:
            ValueError: an opening that is not finite or beyond ``kin.JAW_UPPER_RAD``.
        """
        self.jaw_target = check_float("jaw_angle_rad", jaw_angle_rad, low=None, high=kin.JAW_UPPER_RAD, unit="rad")

    def step(self, q_next: np.ndarray | None = None) -> None:
        """One physics step: the arm moves to ``q_next`` (None: stays), the jaws move.

        Args:
            q_next: joints at the end of this step, (6,) rad / m; the arm moves there at
                constant velocity over the step.
        """
        dt = self.physics.time_step_s
        q_next = self.q if q_next is None else np.asarray(q_next, dtype=float)
        jaw_rates = self._jaw_rates(dt)
        self._drive((q_next - self.q) / dt, jaw_rates)
        self.physics.step()
        self.q = q_next.copy()
        self.half_angles = np.maximum(self.half_angles + jaw_rates * dt, 0.0)
        self._sense()
        self._update_holds()
        for fragment in self.fragments.values():
            fragment.update_compression(self.indentation(fragment.name), dt)
        self._limit_free_speeds()

    def follow(self, joint_path: Iterable[np.ndarray]) -> int:
        """Step through a joint path, one physics step per entry; returns the step count."""
        count = 0
        for q in joint_path:
            self.step(q)
            count += 1
        return count

    def move_tool(self, pose: np.ndarray, speed_m_s: float) -> int:
        """Move the tool frame in a straight line to ``pose`` at ``speed_m_s``, stepping physics.

        Joints come from the nominal inverse kinematics, so this is for a body built
        from the nominal table; a biased world computes its own joint path and calls
        :meth:`follow`. Returns the number of steps taken.
        """
        dt = self.physics.time_step_s
        start = kin.forward_kinematics(self.q)
        distance = float(np.linalg.norm(pose[:3, 3] - start[:3, 3]))
        n = max(1, math.ceil(distance / (speed_m_s * dt)))
        q_ref, path = self.q, []
        for i in range(1, n + 1):
            waypoint = np.array(pose, dtype=float)
            waypoint[:3, 3] = start[:3, 3] + (pose[:3, 3] - start[:3, 3]) * i / n
            q_ref = ik.inverse_kinematics(waypoint, q_ref=q_ref)
            path.append(q_ref)
        return self.follow(path)

    def settle_jaws(self, max_steps: int = 480, still_steps: int = 6) -> int:
        """Step (the arm still) until the jaws stop moving, at most ``max_steps``; returns steps."""
        still = 0
        for count in range(1, max_steps + 1):
            before = self.half_angles.copy()
            self.step()
            still = still + 1 if np.abs(self.half_angles - before).max() < _STILL_RAD else 0
            if still >= still_steps:
                return count
        return max_steps

    def release(self, name: str) -> None:
        """Let go of one fragment (grasped or pierced); nothing happens if it is not held."""
        if name in self.holds:
            self._release(name)

    def release_all(self) -> None:
        """Let go of everything (grasps and pierces), e.g. before rebuilding the world."""
        for name in list(self.holds):
            self._release(name)

    # ------------------------------------------------------------------ jaw drive
    def _jaw_rates(self, dt: float) -> np.ndarray:
        """Opening rate of each jaw for this step, rad/s (+ opens)."""
        goal = max(self.jaw_target, 0.0) / 2
        top = self.config.jaw_speed_rad_s / 2
        squeeze = self._squeeze_goals()
        rates = np.zeros(2)
        for i in range(2):
            target = goal if squeeze is None else max(goal, squeeze[i])
            gap = target - self.half_angles[i]
            if gap > 0.0:
                rates[i] = min(top, gap / dt)
            elif gap < 0.0 and (squeeze is not None or not self._blocked(i)):
                rates[i] = -min(top, -gap / dt)
        return rates

    def _squeeze_goals(self) -> np.ndarray | None:
        """Half-angles at which the jaws press a grasped fragment with the grip force."""
        for name, hold in self.holds.items():
            if hold.mode == "grasp":
                compression = self.config.grip_force_n / self._by_name[name].kind.stiffness_n_m
                return hold.contact_half_angles - compression / 2 / hold.levers_m
        return None

    def _give(self, body: int) -> float:
        """How far a closing jaw may press into a body before it stalls, m: a fragment
        yields as far as the grip force squeezes it, anything else hardly at all."""
        fragment = self.fragments.get(body)
        if fragment is None:
            return self.config.stop_depth_m
        return max(self.config.stop_depth_m, self.config.grip_force_n / fragment.kind.stiffness_n_m)

    def _blocked(self, i: int) -> bool:
        """Whether closing jaw i would press further into something that does not give.

        Only contacts the closing motion pushes into count (a jaw that came down on top
        of a fragment slides over it as it closes), and only once the jaw is in further
        than the body gives (:meth:`_give`).
        """
        pressed = [t for body, t in self._touches[i].items() if t.depth_m >= self._give(body)]
        if not pressed:
            return False
        pose = self.robot.link_pose(JAW_LINKS[i])
        closing_spin = pose[:3, 2] * (-1.0 if i == 0 else 1.0)  # jaw A closes by turning back about its axis
        for touch in pressed:
            velocity = np.cross(closing_spin, touch.jaw_point - pose[:3, 3])
            speed = np.linalg.norm(velocity)
            if speed > 0.0 and velocity @ -touch.normal > _INTO_COS * speed:
                return True
        return False

    def _drive(self, arm_velocity: np.ndarray, jaw_rates: np.ndarray) -> None:
        """Set every joint where it is now, with its velocity for the coming step."""
        self.robot.drive(self.q, self.half_angles, arm_velocity, jaw_rates)

    # ------------------------------------------------------------------ sensing
    def _sense(self) -> None:
        for i, link in enumerate(JAW_LINKS):
            self._touches[i] = holding.sense_touches(self.physics.client, self.robot.body_id, link)

    def _limit_free_speeds(self) -> None:
        c = self.physics.client
        limit = self.config.max_free_speed_m_s
        for body, fragment in self.fragments.items():
            if fragment.name in self.holds:
                continue
            linear, angular = c.getBaseVelocity(body)
            vx, vy, vz = linear
            speed = math.sqrt(vx * vx + vy * vy + vz * vz)  # the order sum() adds them in
            if speed > limit:
                scale = limit / speed
                c.resetBaseVelocity(body, [v * scale for v in linear], [w * scale for w in angular])

    # ------------------------------------------------------------------ holding
    def _update_holds(self) -> None:
        for name in list(self.holds):
            self._check_release(name)
        for fragment in self.fragments.values():
            if fragment.name in self.holds:
                continue
            if fragment.kind.pierceable and self._try_pierce(fragment):
                continue
            self._try_grasp(fragment)

    def _try_grasp(self, fragment: Fragment) -> None:
        """Hold ``fragment`` once both jaws have squeezed it antipodally for ``grasp_steps`` steps in a row."""
        name, body = fragment.name, fragment.body_id
        if body not in self._touches[0] or body not in self._touches[1]:  # the common case: not squeezed
            self._streak[name] = 0
            return
        touching = all(body in self._touches[i] and self._touches[i][body].depth_m >= 0.0 for i in range(2))
        ok = touching and self.jaw_target < self.jaw_angle and self._antipodal(fragment)
        self._streak[name] = self._streak.get(name, 0) + 1 if ok else 0
        if self._streak[name] == 1:  # the squeeze is measured from where both jaws first touched
            self._first_touch[name] = self.half_angles.copy()
        if self._streak[name] < self.config.grasp_steps:
            return
        self._streak[name] = 0
        jaw_points = [self._touches[i][body].jaw_point for i in range(2)]
        capacity = fragment.kind.friction * self.config.jaw_friction * 2.0 * self.config.grip_force_n
        first_touch = np.maximum(self._first_touch.pop(name), self.half_angles)
        self.holds[name] = holding.grasp_hold(
            self.physics.client, self.robot, fragment, jaw_points=jaw_points, contact_half_angles=first_touch, capacity_n=capacity
        )

    def _antipodal(self, fragment: Fragment) -> bool:
        a, b = (self._touches[i][fragment.body_id] for i in range(2))
        return holding.antipodal(fragment, a, b, self.config.jaw_friction)

    def _try_pierce(self, fragment: Fragment) -> bool:
        """Pierce ``fragment`` with a jaw tip pressing end-on into it with its pierce force."""
        if fragment.kind.pierce_force_n is None:  # only pierceable kinds come here
            return False
        depth = fragment.kind.pierce_force_n / fragment.kind.stiffness_n_m
        for i, link in enumerate(JAW_LINKS):
            touch = self._touches[i].get(fragment.body_id)
            if touch is None or touch.depth_m < depth:
                continue
            jaw_pose = self.robot.link_pose(link)
            if holding.tip_presses_end_on(
                jaw_pose, touch, fragment, tip_zone_m=self.config.pierce_tip_zone_m, max_angle_rad=self.config.pierce_max_angle_rad
            ):
                self.holds[fragment.name] = holding.pierce_hold(
                    self.physics.client, self.robot.body_id, link=link, fragment=fragment, jaw_point=touch.jaw_point
                )
                return True
        return False

    def _check_release(self, name: str) -> None:
        hold = self.holds[name]
        if hold.mode == "grasp":
            if np.any(self.half_angles >= hold.contact_half_angles):
                self._release(name)
            return
        if holding.pierce_stretch_m(self.physics.client, self.robot.body_id, hold, self._by_name[name]) > self.config.pierce_tear_m:
            self._release(name)

    def _release(self, name: str) -> None:
        hold = self.holds.pop(name)
        holding.release_hold(self.physics.client, self.robot.body_id, self._by_name[name].body_id, hold)

    # ------------------------------------------------------------------ frames
    def _pose_in_link(self, name: str) -> holding.Transform:
        return holding.pose_in_link(self.physics.client, self.robot.body_id, self.holds[name].link, self._by_name[name].body_id)

    def _restore_pose_in_link(self, name: str, relative: holding.Transform) -> None:
        holding.restore_pose_in_link(
            self.physics.client, self.robot.body_id, link=self.holds[name].link, body=self._by_name[name].body_id, relative=relative
        )
