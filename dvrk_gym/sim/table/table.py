"""The debridement table beside the arm: the fragments on the paper, the gripper, moves that step physics.

:class:`DebridementTable` sits on a :class:`~dvrk_gym.sim.world.DvrkWorld` (the arm, its
cables, the cameras and the clock) and owns what the debridement experiment adds to it:
the fragments, the :class:`~dvrk_gym.sim.table.grasp.Gripper` that lets the jaws push,
grasp and pierce them, and the moves that step physics all the way
(:meth:`~DebridementTable.move_stepped`, :meth:`~DebridementTable.actuate_jaws`,
:meth:`~DebridementTable.dwell`). Once it has laid fragments it is the world's
:class:`~dvrk_gym.sim.world_config.JawDriver`: the world's own moves and resets then drive the
tool through the gripper, so held fragments go along. :meth:`DvrkWorld.rebuild
<dvrk_gym.sim.world.DvrkWorld.rebuild>` empties the table (:meth:`~DebridementTable.detach`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.motion import CartesianMove, trapezoid_progress
from dvrk_gym.sim.robot.motion_limits import MotionLimits
from dvrk_gym.sim.table.contact import COMPLIANT, PaperContact
from dvrk_gym.sim.table.fragment_types import FragmentType
from dvrk_gym.sim.table.fragments import FRAGMENTS_PER_TRIAL, Fragment, sample_fragment_sizes, spawn_fragments
from dvrk_gym.sim.table.grasp import Gripper
from dvrk_gym.sim.table.gripper_config import GripperConfig
from dvrk_gym.sim.table.layout import sample_layout
from dvrk_gym.sim.world import DvrkWorld, MoveResult
from dvrk_gym.utils.checks import check_float, check_int

PARKING_ORIGIN_M = np.array([0.14, -0.03, -0.175])
PARKING_PITCH_M = 0.015
"""Where fragments taken out of play are parked (on the tray, out of the paper's view), metres."""
FRAGMENT_SETTLE_STEPS = 24
"""Physics steps (0.1 s) that let new fragments settle onto the paper before a trial."""
MAX_JAW_SETTLE_S = 2.0
"""Longest :meth:`DebridementTable.actuate_jaws` waits for the jaws to stop, seconds."""
MAX_STEPPED_S = 60.0
"""The longest wait, jaw actuation or stepped move a table takes, seconds (a pick's phases take one or two)."""
MAX_FRAGMENTS = 64
"""The most fragments :meth:`DebridementTable.add_fragments` lays (a trial: 8)."""
MAX_TIP_CLEARANCE_M = 0.05
"""The largest floor :meth:`DebridementTable.move_stepped` keeps the tip above or below the paper, m."""


class DebridementTable:
    """The fragments on the paper and the gripper that acts on them, beside a world's arm.

    Args:
        world: the arm, its cables, the cameras and the clock; the table drives its tool
            once it has fragments (see :class:`~dvrk_gym.sim.world_config.JawDriver`).
        gripper_config: grip force, jaw speed, friction and contact thresholds of the
            gripper each :meth:`add_fragments` makes (None: the defaults).
        contact: how the paper takes a move sent under :meth:`move_stepped`'s floor: the
            jaws slide along it by ``contact.slide_m`` of the depth
            (:mod:`dvrk_gym.sim.table.contact`; GridTouch-v0's paper). Default: the
            identified paper.

    Attributes:
        fragments: the fragments laid since the world was last rebuilt, in spawn order.
        gripper: the gripper acting on them; None until :meth:`add_fragments`.
    """

    def __init__(self, world: DvrkWorld, gripper_config: GripperConfig | None = None, contact: PaperContact = COMPLIANT) -> None:
        if not isinstance(contact, PaperContact):
            raise ValueError(f"contact must be a PaperContact, got {type(contact).__name__}")
        self.world = world
        self.gripper_config = gripper_config
        self.contact = contact
        self.fragments: list[Fragment] = []
        self.gripper: Gripper | None = None

    # ----------------------------------------------------------------- fragments
    def add_fragments(self, kind: str | FragmentType, rng: np.random.Generator, n: int = FRAGMENTS_PER_TRIAL) -> list[Fragment]:
        """Lay ``n`` fragments of ``kind`` at random on the paper and make the jaws able to hold them.

        Sizes, positions and orientations are drawn from ``rng`` (the paper's sizes, at
        least 3 mm apart, any orientation); the fragments settle for
        FRAGMENT_SETTLE_STEPS physics steps (not counted on the clock). From now on the
        world's tool moves through the :class:`~dvrk_gym.sim.table.grasp.Gripper`.

        Raises:
            RuntimeError: if the world has fragments (of this table or another) since it
                was last rebuilt.
            ValueError: ``n`` not an int in [0, ``MAX_FRAGMENTS``], or ``rng`` not a
                numpy Generator.
        """
        n = check_int("n", n, 0, MAX_FRAGMENTS)
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy Generator (np.random.default_rng(seed)), got {type(rng).__name__}")
        world = self.world
        if self.gripper is not None or world.jaw_driver is not None:
            raise RuntimeError("this world already has fragments; call world.rebuild() first")
        sizes = sample_fragment_sizes(kind, rng, n)
        positions, yaws = sample_layout(rng, sizes=sizes)
        self.fragments = spawn_fragments(world.physics, kind=kind, sizes=sizes, positions=positions, yaws=yaws)
        self.gripper = Gripper(world.physics, world.robot, self.fragments, self.gripper_config)
        world.jaw_driver = self
        for _ in range(FRAGMENT_SETTLE_STEPS):
            self.gripper.step()
        return self.fragments

    def set_aside_fragment(self, index: int) -> None:
        """Take fragment ``index`` out of play, as the operator does with a failed one.

        It is let go of (even if pierced), and parked on the tray far outside the camera's
        view of the paper, where it stays still and touches nothing.

        Raises:
            ValueError: ``index`` is not that of a fragment laid (0 .. len(fragments) - 1).
        """
        gripper = self._require_gripper()
        index = check_int("index", index, 0, len(self.fragments) - 1)
        fragment = self.fragments[index]
        gripper.release(fragment.name)
        c = self.world.physics.client
        parking = [PARKING_ORIGIN_M[0], PARKING_ORIGIN_M[1] + PARKING_PITCH_M * index, PARKING_ORIGIN_M[2]]
        c.changeDynamics(fragment.body_id, -1, mass=0.0)
        c.setCollisionFilterGroupMask(fragment.body_id, -1, 0, 0)
        c.resetBasePositionAndOrientation(fragment.body_id, parking, [0.0, 0.0, 0.0, 1.0])
        c.resetBaseVelocity(fragment.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])

    def held(self) -> dict[int, str]:
        """The fragments the jaws hold now, by index, each with "grasp" or "pierce" (truth)."""
        if self.gripper is None:
            return {}
        modes = self.gripper.held()
        return {i: modes[f.name] for i, f in enumerate(self.fragments) if f.name in modes}

    def true_fragment_positions(self) -> np.ndarray:
        """Centres of the fragments, (n, 3) base frame, metres. Evaluation only."""
        return np.array([f.position() for f in self.fragments]).reshape(-1, 3)

    # ----------------------------------------------------------------- moves that step physics
    def move_stepped(
        self,
        pose: np.ndarray,
        *,
        noise_rng: np.random.Generator | None = None,
        min_tip_clearance_m: float | None = None,
        limits: MotionLimits | None = None,
        duration_s: float | None = None,
    ) -> MoveResult:
        """Move the tool frame in a straight line to ``pose``, stepping physics all the way.

        The move is the same trapezoidal profile as :meth:`DvrkWorld.move_to
        <dvrk_gym.sim.world.DvrkWorld.move_to>`, sampled at the physics time step; every
        sample goes through the nominal inverse kinematics (the joint command) and the
        cable model (the true joints the jaws follow), so the jaws push, squeeze and lift
        what they meet. This move's repeatability noise is blended in along the way from
        the last move's, and the wrist settles short of the command once a move
        (``BiasConfig.wrist_settle_lag``), as after :meth:`~dvrk_gym.sim.world.DvrkWorld.move_to`.

        Args:
            pose: the commanded tool pose (4x4, base frame, metres); clamped to the
                joint limits (reported in the result).
            noise_rng: the generator for this move's repeatability noise (None: none).
            min_tip_clearance_m: keep the closed jaw tip at least this high above the
                paper: the part of the path below is raised onto that floor, where the
                tool stalls (the silicone under the paper gives; the jaws do not dig in),
                and the jaws slide along it as far as the table's ``contact`` slides jaws
                sent that deep under the paper (as GridTouch-v0's touches are; the encoders
                do not see it), metres; None: no floor.
            limits: speed limits of this move (default: the world's).
            duration_s: make the move last exactly this long at constant speed, with
                no settling (a control period), seconds in (0, ``MAX_STEPPED_S``]; None: the
                trapezoidal profile.

        Raises:
            ValueError: a duration or a clearance out of range (``MAX_TIP_CLEARANCE_M``).
        """
        if duration_s is not None:
            duration_s = check_float("duration_s", duration_s, low=0.0, high=MAX_STEPPED_S, low_open=True, unit="s")
        if min_tip_clearance_m is not None:
            min_tip_clearance_m = check_float(
                "min_tip_clearance_m", min_tip_clearance_m, low=-MAX_TIP_CLEARANCE_M, high=MAX_TIP_CLEARANCE_M, unit="m"
            )
        world = self.world
        gripper = self._require_gripper()
        q_target, clamped = ik.inverse_kinematics_clamped(pose, q_ref=world.q_cmd)
        end = kin.forward_kinematics(q_target)
        if duration_s is None:
            move = CartesianMove.plan(world.reported_pose(), end, limits or world.config.motion)
        else:
            move = CartesianMove(world.reported_pose(), end, duration_s, 0.0)
        dt = world.physics.time_step_s
        offset_start = world.q_true - world.cable.resting_true_joints(world.q_cmd)  # the last move's noise (and slide)
        floor = None if min_tip_clearance_m is None else float(WORKSPACE_CENTER_M[2]) + min_tip_clearance_m
        commands, trues, slides = self._joint_path(move, offset_start, floor)
        noise_end = np.zeros(len(offset_start)) if noise_rng is None else world.cable.repeatability_draw(noise_rng)
        fractions = np.arange(1, len(commands) + 1)[:, None] / len(commands)
        path = np.array(trues) + (1.0 - fractions) * offset_start + fractions * noise_end
        for i, slide in slides.items():
            path[i] += slide
        steps = gripper.follow(path)
        world.q_cmd, world.q_true = np.array(commands[-1]), path[-1].copy()
        world.jaw_angle = gripper.jaw_angle
        settle = 0.0 if duration_s is not None else self.dwell((limits or world.config.motion).settle_time_s)
        elapsed = steps * dt + settle
        world.clock.advance(steps * dt)
        return MoveResult(elapsed, world.q_cmd.copy(), world.q_true.copy(), clamped)

    def _joint_path(self, move: CartesianMove, offset_start: np.ndarray, floor: float | None) -> tuple[list, list, dict[int, np.ndarray]]:
        """The joint commands of a stepped move, the true joints the cables make of them, and
        how far the paper's slide moves the true joints, by waypoint (only those it moves).

        Args:
            move: the Cartesian move, sampled every physics step.
            offset_start: the true joints' offset from the cable model's at the start
                (the last move's repeatability noise, and its slide on the paper), rad / m.
            floor: the lowest height the closed jaw tip may reach, base frame z, m; None:
                no floor. A waypoint that would take the tip under it is raised onto it; if
                it would take the tip ``depth`` under the paper (where GridTouch-v0's touches
                meet it), the slide there moves the true joints so that the jaws slide by the
                contact's slide at that depth, while the command (what the encoders report) stays.
        """
        cable = self.world.cable
        slides = self.contact.slides
        paper_z = float(WORKSPACE_CENTER_M[2])
        commands: list[np.ndarray] = []
        trues: list[np.ndarray] = []
        slid: dict[int, np.ndarray] = {}
        q_ref = self.world.q_cmd
        motors = cable.get_state()[-1]  # the wrist settles short once a move, as move_to's does
        for waypoint in _waypoints(move, self.world.physics.time_step_s):
            state = cable.get_state()
            q_ref, _ = ik.inverse_kinematics_clamped(waypoint, q_ref=q_ref)
            q_true = cable.true_joints(q_ref, settle_from=motors)
            if floor is not None:
                gap = kin.touch_point(q_true + offset_start, cable.true_dh)[2] - floor
                if gap < 0.0:  # the tip stays on the floor: lift this waypoint by the gap (the
                    # true tip follows the command one for one in height)
                    cable.set_state(state)
                    lifted = waypoint.copy()
                    lifted[2, 3] -= gap
                    q_ref, _ = ik.inverse_kinematics_clamped(lifted, q_ref=commands[-1] if commands else self.world.q_cmd)
                    q_true = cable.true_joints(q_ref, settle_from=motors)
                    depth = paper_z - (floor + gap)  # how far under the paper the tip was sent
                    if slides and depth > 0.0:
                        lifted[:2, 3] += self.contact.slide_m(depth)
                        q_slid, _ = ik.inverse_kinematics_clamped(lifted, q_ref=q_ref)
                        slid[len(commands)] = q_slid - q_ref
            commands.append(q_ref)
            trues.append(q_true)
        return commands, trues, slid

    def actuate_jaws(self, jaw_angle_rad: float, duration_s: float | None = None) -> float:
        """Command the jaws to an opening (rad; <= 0 closes as far as what they hold allows).

        Physics steps with the arm still, for ``duration_s`` seconds or, when None, until
        the jaws stop moving (at most MAX_JAW_SETTLE_S). Returns the simulated seconds
        taken (also added to the clock). ValueError for a duration outside [0, ``MAX_STEPPED_S``] s.
        """
        if duration_s is not None:
            duration_s = check_float("duration_s", duration_s, low=0.0, high=MAX_STEPPED_S, unit="s")
        gripper = self._require_gripper()
        gripper.command_jaw(jaw_angle_rad)
        dt = self.world.physics.time_step_s
        if duration_s is None:
            steps = gripper.settle_jaws(max_steps=int(round(MAX_JAW_SETTLE_S / dt)))
        else:
            steps = int(round(duration_s / dt))
            for _ in range(steps):
                gripper.step()
        self.world.jaw_angle = gripper.jaw_angle
        self.world.clock.advance(steps * dt)
        return steps * dt

    def command_jaws(self, jaw_angle_rad: float) -> None:
        """Set the opening the jaws move towards from the next physics step on (rad; <= 0
        closes as far as what they hold allows); nothing is stepped here."""
        self._require_gripper().command_jaw(jaw_angle_rad)

    def dwell(self, seconds: float, step_physics: bool = True) -> float:
        """Wait ``seconds`` with the arm still (physics stepped, if asked and there are
        fragments); returns the simulated seconds taken (also added to the clock). A wait of
        zero or less (what is left of a phase another step overran) takes none; ValueError
        for one that is not finite or above ``MAX_STEPPED_S``."""
        seconds = check_float("seconds", seconds, low=None, high=MAX_STEPPED_S, unit="s")
        dt = self.world.physics.time_step_s
        steps = max(0, int(round(seconds / dt)))
        if step_physics and self.gripper is not None:
            for _ in range(steps):
                self.gripper.step()
        self.world.clock.advance(steps * dt)
        return steps * dt

    # ----------------------------------------------------------------- the world's jaw driver
    def place_tool(self, q_true: np.ndarray, jaw_angle_rad: float | None) -> float:
        """:class:`~dvrk_gym.sim.world_config.JawDriver`: teleport the tool (held fragments go along)."""
        gripper = self._require_gripper()
        gripper.place(q_true, jaw_angle_rad)
        return gripper.jaw_angle

    def reset_tool(self, q_true: np.ndarray, jaw_angle_rad: float) -> None:
        """:class:`~dvrk_gym.sim.world_config.JawDriver`: nothing stays held through a reset."""
        gripper = self._require_gripper()
        gripper.release_all()
        gripper.place(q_true, jaw_angle_rad)

    def detach(self) -> None:
        """:class:`~dvrk_gym.sim.world_config.JawDriver`: let go of everything and forget the
        fragments and the gripper (the world is about to empty its physics server)."""
        if self.gripper is not None:
            self.gripper.release_all()
        self.fragments, self.gripper = [], None

    def _require_gripper(self) -> Gripper:
        if self.gripper is None:
            raise RuntimeError("this table has no fragments; call add_fragments() first")
        return self.gripper


def _waypoints(move: CartesianMove, dt_s: float) -> np.ndarray:
    """Poses every ``dt_s`` seconds along a move, ending at its end: (n, 4, 4).

    The same poses as ``move.waypoints(dt_s)``, with one slerp for the whole move.
    """
    n = max(1, math.ceil(move.duration_s / dt_s))
    progress = np.array([trapezoid_progress(move.duration_s * (i + 1) / n, move.duration_s, move.ramp_s) for i in range(n)])
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, 3] = (1.0 - progress)[:, None] * move.start[:3, 3] + progress[:, None] * move.end[:3, 3]
    rotations = Rotation.from_matrix(np.stack([move.start[:3, :3], move.end[:3, :3]]))
    poses[:, :3, :3] = Slerp([0.0, 1.0], rotations)(progress).as_matrix()
    return poses
