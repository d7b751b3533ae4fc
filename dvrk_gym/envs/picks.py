"""The pick primitive of Debridement-v0: the paper's six phases, from a commanded target to the drop.

One pick starts from a base-frame target ``(bx, by, bz)`` and a yaw: the commanded
(reported) position that should put the closed jaw tip on a fragment. It moves to above
the target in free space with the jaws open (``to_seed``), lowers them stepping physics
onto a floor just above the paper (``lower``; a target under the paper slides them along
it, :class:`~dvrk_gym.sim.table.table.DebridementTable`), closes them (``grip``), lifts (``raise``),
carries what it holds to the receptacle (``to_receptacle``), opens the jaws and turns the
tool back to yaw 0 (``drop_and_rotate``). :class:`PickTiming` sets its heights, speeds
and dwells; :class:`PickPrimitive` runs it on a world and its table and returns what the
judge (:mod:`dvrk_gym.sim.table.judge`) needs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dvrk_gym import paper
from dvrk_gym.envs.debridement_config import PickTiming
from dvrk_gym.envs.tool_pose import tool_pose
from dvrk_gym.sim.physics.scene import RECEPTACLE_CENTER_M
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.table import judge
from dvrk_gym.sim.table.grasp import GRASP_TIP_CLEARANCE_M
from dvrk_gym.sim.table.table import DebridementTable
from dvrk_gym.sim.world import DvrkWorld

PHASES: tuple[str, ...] = tuple(paper.DEBRIDEMENT_PHASE_FRAMES)
"""The paper's six phases of a pick, in order."""
CLOSED_JAW_RAD = kin.JAW_LOWER_RAD
"""The jaw command that closes the jaws as far as what they hold allows."""
DROP_OFFSETS_M = np.array([[x, y] for y in (-0.007, 0.0, 0.007) for x in (-0.006, 0.0, 0.006)])
"""Where in the receptacle successive picks drop the jaw tip (about its centre, metres):
eight raisins dropped at one point pile over the rim."""
TEACH_ITERATIONS = 4
"""Fixed-point iterations that find the command putting the true jaw tip on a drop point."""

ABORTED_PICK_INFO: dict[str, object] = {
    "outcome": None,
    "pick_fragment": -1,
    "true_grip_offset_ratio": float("inf"),
    "true_grip_offset_m": None,
    "true_tip_at_grip": None,
    "true_tip_above_fragment_m": None,
    "phase_times_s": dict.fromkeys(PHASES, 0.0),
    "pick_time_s": 0.0,
}
"""A pick's step info when the physics failed with an exception during it: the pick has no
outcome (None), judged no fragment (-1) and took no time that counts."""


@dataclass(frozen=True)
class PickRun:
    """What one pick did, for the judge.

    Attributes:
        record: where the jaws were when they began to close, against the fragment they
            took (held when the grip ended), or, if they took none, the fragment of those on
            the paper before the pick they came nearest to (None: none was on the paper).
        pierced: indices of the fragments a jaw tip held pierced at the end of a phase.
        phase_s: how long each of PHASES took, s, (6,).
        joints_clamped: which joints a move had to clamp into their limits, bool (6,).
    """

    record: judge.GripRecord | None
    pierced: set[int]
    phase_s: np.ndarray
    joints_clamped: np.ndarray


class PickPrimitive:
    """The paper's pick on a world and the table beside it.

    Args:
        world: the arm, its cables and the clock.
        table: the fragments and the gripper beside it.
        timing: heights, speeds and dwell times of a pick.

    Attributes:
        on_phase: called at the end of each of the six phases (None: nothing); the env uses
            it to render the frames of a pick.
    """

    def __init__(self, world: DvrkWorld, table: DebridementTable, timing: PickTiming) -> None:
        self.world = world
        self.table = table
        self.timing = timing
        self.on_phase: Callable[[], None] | None = None

    def drop_point(self, pick: int) -> np.ndarray:
        """Where the closed jaw tip should be when pick number ``pick`` drops, base frame, m."""
        offset = DROP_OFFSETS_M[pick % len(DROP_OFFSETS_M)]
        return RECEPTACLE_CENTER_M + [offset[0], offset[1], self.timing.drop_height_m]

    def drop_command(self, pick: int, yaw: float) -> np.ndarray:
        """The commanded position (base frame, m) that puts the true jaw tip on the drop
        point of pick number ``pick`` with tool yaw ``yaw`` (rad), as taught.

        The receptacle lies outside the calibrated workspace, where the uncalibrated
        robot misses by about 9 mm; on the real robot the drop pose is taught once by
        hand. Here the teaching is a fixed-point search on the cable model at rest (no
        noise), which leaves its state as it was.
        """
        cable = self.world.cable
        state = cable.get_state()
        tip = self.drop_point(pick)
        command = tip.copy()
        for _ in range(TEACH_ITERATIONS):
            q, _ = ik.inverse_kinematics_clamped(tool_pose(command, yaw), q_ref=self.world.q_cmd)
            cable.reset(q)
            command = command + tip - kin.jaw_tip_positions(cable.true_joints(q), 0.0, cable.true_dh)[0]
        cable.set_state(state)
        return command

    def run(
        self, target: np.ndarray, yaw: float, *, rng: np.random.Generator, pick: int, sizes: np.ndarray, candidates: list[int]
    ) -> PickRun:
        """Pick at ``target`` (commanded position, base frame, m) with tool yaw ``yaw`` (rad).

        Args:
            rng: draws every move's repeatability noise.
            pick: the pick's number in the episode (which drop point it uses).
            sizes: (n, 3) sizes of the table's fragments, m.
            candidates: indices of the fragments on the paper before the pick.
        """
        world, table, timing = self.world, self.table, self.timing
        poses_before = [f.pose() for f in table.fragments]
        pierced: set[int] = set()
        marks = [world.clock.time_s]
        joints_clamped = np.zeros(6, dtype=bool)

        def phase_done() -> None:
            marks.append(world.clock.time_s)
            pierced.update(i for i, mode in table.held().items() if mode == "pierce")
            if self.on_phase is not None:
                self.on_phase()

        above = tool_pose(target + [0.0, 0.0, timing.approach_height_m], yaw)
        move = world.move_to(above, jaw_angle_rad=kin.JAW_FULLY_OPEN_RAD, noise_rng=rng, clamp_to_limits=True, limits=timing.travel)
        joints_clamped |= move.joints_clamped
        phase_done()
        move = table.move_stepped(
            tool_pose(target - [0.0, 0.0, timing.grip_depth_m], yaw),
            noise_rng=rng,
            min_tip_clearance_m=GRASP_TIP_CLEARANCE_M,
            limits=timing.descend,
        )
        joints_clamped |= move.joints_clamped
        tip = world.true_touch_point()
        phase_done()
        spent = table.actuate_jaws(CLOSED_JAW_RAD)
        table.dwell(timing.grip_dwell_s - spent, step_physics=False)
        # The pick is the fragment the jaws took, if they took one (a neighbour may lie
        # nearer the tip as they close); else the one they came nearest to.
        taken = [i for i in table.held() if i in candidates]
        record = judge.grip_record(tip, poses_before, sizes, taken or candidates)
        phase_done()
        lifted = world.reported_pose()[:3, 3] + [0.0, 0.0, timing.raise_height_m]
        table.move_stepped(tool_pose(lifted, yaw), noise_rng=rng, limits=timing.descend)
        phase_done()
        drop = self.drop_command(pick, yaw)
        world.move_to(tool_pose(drop, yaw), jaw_angle_rad=None, noise_rng=rng, clamp_to_limits=True, limits=timing.carry)
        phase_done()
        spent = table.actuate_jaws(kin.JAW_FULLY_OPEN_RAD, timing.drop_fall_s)
        spent += world.move_to(
            tool_pose(drop, 0.0), jaw_angle_rad=None, noise_rng=rng, clamp_to_limits=True, limits=timing.travel
        ).duration_s
        table.dwell(timing.drop_dwell_s - spent, step_physics=False)
        phase_done()  # a raisin pierced as it drops counts too
        return PickRun(record, pierced, np.diff(marks), joints_clamped)
