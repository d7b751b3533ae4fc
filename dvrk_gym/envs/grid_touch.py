"""GridTouch-v0: touch the 35 printed circles (the paper's Phase II and its benchmark).

Goal-conditioned: the desired goal is a circle's centre as the endoscope sees it
(triangulated, left camera frame, metres); the achieved goal is the touch point of the
closed jaws as the endoscope sees it. The action is the base-frame command
``(bx, by, bz, yaw)`` of the tool frame (metres, radians): the wrist pivot, which the robot
reports, with the closed jaw tip 10 mm beyond it along the jaws (pitch and roll follow from
yaw by the paper's rule). A step goes above the target, moves down to the command, and
records the touch. A command under the paper ends as the ``contact`` option says
(:mod:`dvrk_gym.sim.table.contact`): by default the arm goes on down, stopping short of its
command (it reports itself over it), and the jaws slide along the paper, as the authors'
records show the real robot's did; ``contact="rigid"`` stops where the jaws meet the paper.

An episode is one touch of one circle, and successive episodes tour the 35 circles in
the authors' order (:data:`TOUR`; a seeded reset starts the tour again), so the goal stays fixed within an
episode, as HER's relabelling and stable-baselines3's GoalEnv check require. The paper's
35-circle pass for one yaw is 35 consecutive episodes.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces

from dvrk_gym.envs.base import DvrkEnv, config_arguments, relax_option
from dvrk_gym.envs.configs import GridTouchConfig
from dvrk_gym.envs.exploration import CAMERA_BOX_HIGH_M, CAMERA_BOX_LOW_M, encode_reported
from dvrk_gym.envs.tool_pose import tool_pose, tool_rotation
from dvrk_gym.sim.compiled import float_paths
from dvrk_gym.sim.physics.scene import GRID_COLUMNS, GRID_ROWS, WORKSPACE_CENTER_M, grid_circle_centers
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig
from dvrk_gym.sim.table.contact import CONTACTS, DEFAULT_CONTACT
from dvrk_gym.sim.world_config import MoveResult
from dvrk_gym.utils.checks import check_int

N_CIRCLES = GRID_ROWS * GRID_COLUMNS
TOUR: tuple[int, ...] = tuple(row * GRID_COLUMNS + column for row in range(GRID_ROWS) for column in reversed(range(GRID_COLUMNS)))
"""The authors' tour of the circles, as circle indices (row-major): row by row along the robot's
+y (down the endoscope's image), each row from +x to -x (left to right in the image). Every run
of their calibration table and every round of their Phase II pushes went so (their records:
:func:`dvrk_gym.calibration.datasets.load_paper_table_runs`). Their printed grid was not this
one: 8 staggered rows of 4 or 5 circles about 16 mm apart, so a pass moved 27 times towards -x
and returned to +x 7 times; on this grid of 5 rows of 7 circles 10 mm apart it moves 30 times
towards -x and returns 4 times. The cables keep their history from one touch to the next, so
the direction is part of the protocol: successive episodes tour it, and Phase II and the
benchmark follow it."""
_NEXT_IN_TOUR: tuple[int, ...] = tuple(TOUR[(TOUR.index(circle) + 1) % N_CIRCLES] for circle in range(N_CIRCLES))
"""The circle after each circle (by index) in :data:`TOUR`, the last back to the first: looked up at every reset."""
ACTION_NAMES = ("bx", "by", "bz", "yaw")
ACTION_LOW = np.array([0.0, 0.0, -0.175, -np.pi / 2])
ACTION_HIGH = np.array([0.080, 0.085, -0.130, np.pi / 2])
SURFACE_Z_M = float(WORKSPACE_CENTER_M[2])
CONTACT_TOLERANCE_M = 1e-7
"""How exactly the descent finds the height where the jaws meet the paper, metres."""
TOUCH_HEIGHT_TOLERANCE_M = 1e-4
"""A touch whose true tip ends at most this far over the paper touched it (a rigid paper stops it 0.06 mm under), metres."""
MAX_NOISE_DRAWS = 1000  # a noisy left/right pair with no positive disparity is drawn again, at most this often
HOME_POSITION_M = np.array([0.040, 0.042, -0.130])
"""Where a fresh or relaxed episode starts: the reported point 34 mm above the middle of the grid, metres."""


def _check_yaw_option(yaw: Any) -> float | str:
    message = f"option 'yaw' must be a number in [-pi/2, pi/2] or 'random', got {yaw!r}"
    if isinstance(yaw, str):
        if yaw != "random":
            raise ValueError(message)
        return yaw
    if isinstance(yaw, (bool, np.bool_)) or not isinstance(yaw, numbers.Real):  # no bools, complex numbers or text
        raise ValueError(message)
    try:
        value = float(yaw)
    except OverflowError:  # an int beyond any float (10**400)
        raise ValueError("option 'yaw' must be a number in [-pi/2, pi/2] or 'random', got a number too large for a float") from None
    if not (np.isfinite(value) and abs(value) <= np.pi / 2 + 1e-6):  # the env's own float32 yaw of +-pi/2 is 4e-8 beyond
        raise ValueError(message)
    return min(max(value, -np.pi / 2), np.pi / 2)


def _clip_camera(position: np.ndarray) -> np.ndarray:
    return np.clip(position, CAMERA_BOX_LOW_M, CAMERA_BOX_HIGH_M).astype(np.float32)


_HOME_COMMAND = ik.inverse_kinematics(tool_pose(HOME_POSITION_M, 0.0))
_HOME_COMMAND.flags.writeable = False
"""The joint command of ``HOME_POSITION_M`` at yaw 0, rad / m."""


class GridTouchEnv(DvrkEnv[GridTouchConfig]):
    """Touch a grid circle; successive episodes tour all 35 (the paper's Phase II and benchmark).

    Observation (a Dict, as HER wants): ``observation`` = reported (bx, by, bz) m,
    (yaw, pitch, roll) rad, jaw angle rad, and the yaw to use for this circle, rad;
    ``desired_goal`` = the circle's centre seen by the endoscope, (x, y, z) left camera
    frame, m; ``achieved_goal`` = the touch point of the closed jaws seen by the endoscope
    (before the touch: where the jaws are).

    Reset options:
        ``"yaw"``: a yaw (rad, in [-pi/2, pi/2]) for this and later circles, or
            ``"random"``: a random yaw per circle (the paper's sixth setting). Default 0;
            the setting persists through unseeded resets; a seeded one returns it to 0, as
            a fresh env has it.
        ``"circle"``: which circle (0-34, row-major) to touch; default: the next one of
            the authors' tour (:data:`TOUR`; its first, circle 6, after a seeded reset).
        ``"relax"``: True starts the episode at home (``HOME_POSITION_M``, yaw 0) with
            relaxed cables, as a fresh env does. False: the arm lifts
            ``approach_height_m`` straight up from its last touch (or stays where it is
            if it has not touched since the last reset) and its cables keep their
            history, so each touch meets the hysteresis the touches before it left, as on
            the real robot, which lifted from one circle and went on to the next.
            Default: True for a seeded reset (a seed then fixes the episode: the tour,
            the yaw setting and the cables start as in a fresh env), False otherwise;
            ``reset(seed=s, options={"relax": False})`` keeps the history with a new
            random stream (the same seed and history give the same episode).
    """

    config_class = GridTouchConfig
    action_names = ACTION_NAMES
    option_names = ("yaw", "circle", "relax")
    carried_attributes = ("_next_circle", "_yaw_setting", "_touched")  # the tour, the yaw and where the next episode starts

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        bias: str | BiasConfig = "paper",
        bias_seed: int = 0,
        reward_type: str = "dense",
        distance_threshold_m: float = 0.001,
        approach_height_m: float = 0.008,
        correction_noise_m: float = 0.0002,
        contact: str = DEFAULT_CONTACT,
        camera_resolution: tuple[int, int] = (1920, 1080),
        pixel_noise_px: float = 0.0,
        render_resolution: tuple[int, int] | None = None,
        renderer: str = "auto",
    ) -> None:
        """GridTouch-v0, set up by the fields of :class:`GridTouchConfig` (listed below).

        Raises:
            ValueError: a bad field, or a ``camera_resolution`` at which the endoscope loses a
                printed circle (its goal; the message names the circles).
        """
        super().__init__(GridTouchConfig(**config_arguments(locals())), render_mode=render_mode)
        self.action_space = spaces.Box(ACTION_LOW.astype(np.float32), ACTION_HIGH.astype(np.float32), dtype=np.float32)
        goal = spaces.Box(CAMERA_BOX_LOW_M.astype(np.float32), CAMERA_BOX_HIGH_M.astype(np.float32), dtype=np.float32)
        obs_low = np.array([-0.3, -0.3, -0.3, -np.pi, -np.pi, -np.pi, kin.JAW_LOWER_RAD, -np.pi / 2], dtype=np.float32)
        obs_high = np.array([0.3, 0.3, 0.3, np.pi, np.pi, np.pi, kin.JAW_UPPER_RAD, np.pi / 2], dtype=np.float32)
        self.observation_space = spaces.Dict(
            {"observation": spaces.Box(obs_low, obs_high, dtype=np.float32), "achieved_goal": goal, "desired_goal": goal}
        )
        self.circle_centers = grid_circle_centers()
        self._paper = CONTACTS[self.config.contact]
        self._next_circle = TOUR[0]
        self._yaw_setting: float | str = 0.0
        self._circle = 0
        self._yaw = 0.0
        self._achieved = np.zeros(3)
        self._touched = False  # whether the arm touched the paper since the last reset
        # The goals are the circles as the endoscope sees them: a resolution that loses one
        # (128 x 72 loses five, whose goals would be NaN) is refused now, not at its episode.
        missed = [i for i, seen in enumerate(self.world.observe_grid()) if not np.isfinite(seen.camera_position).all()]
        if missed:
            self.close()
            width, height = self.config.camera_resolution
            raise ValueError(
                f"at a camera_resolution of {width} x {height} px the endoscope does not find printed circle(s) {missed} "
                "in both images, and GridTouch-v0's goals are those circles; use another resolution "
                "(320 x 180 and the default 1920 x 1080 find all 35)"
            )

    # ------------------------------------------------------------------ episode
    def _check_options(self, options: dict[str, Any], seeded: bool) -> None:
        super()._check_options(options, seeded)
        if "yaw" in options:
            _check_yaw_option(options["yaw"])
        if "circle" in options:
            check_int("option 'circle'", options["circle"], 0, N_CIRCLES - 1)

    def _check_carried_attributes(self, attributes: dict[str, Any]) -> None:
        check_int("carried '_next_circle'", attributes["_next_circle"], 0, N_CIRCLES - 1)
        try:
            _check_yaw_option(attributes["_yaw_setting"])
        except ValueError as error:
            raise ValueError(f"carried '_yaw_setting': {error}") from None
        if not isinstance(attributes["_touched"], bool):
            raise ValueError(f"carried '_touched' must be True or False, got {attributes['_touched']!r}")

    def _reset_episode(self, options: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        if self._seeded_reset:  # a seed starts the tour again at a fresh env's yaw: it alone fixes the episode
            self._next_circle, self._yaw_setting = TOUR[0], 0.0
        if "yaw" in options:
            self._yaw_setting = _check_yaw_option(options["yaw"])
        self._circle = int(options.get("circle", self._next_circle))
        self._next_circle = _NEXT_IN_TOUR[self._circle]
        if self._yaw_setting == "random":
            self._yaw = float(self.np_random.uniform(-np.pi / 2, np.pi / 2))
        else:
            self._yaw = float(self._yaw_setting)
        relax = relax_option(options, self._seeded_reset)
        # The physics was restored to the env's start, but the cable model is not physics:
        # its hysteresis state carries over unless the user asks for relaxed cables.
        self.world.reset_robot(self._start_joints(relax), relax=relax, floats=True)
        self._touched = False
        self._achieved = self._seen_touch_point(self.world.camera.project_point_floats(self._true_touch_point().tolist()))
        info = {"circle_index": self._circle, "target_yaw": self._yaw, "sim_time_s": 0.0}
        return self._observation(), info

    def _start_joints(self, relax: bool) -> np.ndarray:
        """The joint command an episode starts at: home for a relaxed or fresh arm (no
        cable history yet); else lifted by ``approach_height_m`` from the last touch, or
        where the arm is when it has not touched since the last reset."""
        world = self.world
        if relax or not np.isfinite(world.cable.get_state()).all():
            return _HOME_COMMAND
        if not self._touched:
            return world.q_cmd.copy()
        lifted = world.reported_pose()
        lifted[2, 3] += self.config.approach_height_m
        return np.array(float_paths.inverse_kinematics_clamped(lifted[:3, 3], lifted[:3, :3], world.q_cmd))

    def _step_episode(self, action: np.ndarray, clamped: np.ndarray):
        target, yaw = action[:3], float(action[3])
        above = target + [0.0, 0.0, self.config.approach_height_m]
        first = self._move(above, yaw)
        contact_z, target_z = self._contact_height(target, yaw), float(target[2])
        touch = self._move(np.array([target[0], target[1], self._paper.command_height(contact_z, target_z)]), yaw)
        tip = self._paper.touch_point(self._true_touch_point(), contact_z - target_z, SURFACE_Z_M)
        pixels = self.world.camera.project_point_floats(tip.tolist())
        self._achieved = self._seen_touch_point(pixels)
        self._touched = True
        info = self._touch_info(yaw, clamped, first.joints_clamped | touch.joints_clamped, tip, np.array(pixels[:2]))
        observation = self._observation()
        reward = float(self.compute_reward(observation["achieved_goal"], observation["desired_goal"], info))
        distance = float(np.linalg.norm(observation["achieved_goal"] - observation["desired_goal"]))
        info["is_success"] = distance <= self.config.distance_threshold_m
        info["sim_time_s"] = self.world.clock.time_s
        return observation, reward, True, False, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Reward for goals (..., 3) in metres, vectorised over leading axes (for HER).

        Dense: minus the distance in millimetres. Sparse: 0 within the success radius, else -1.
        ValueError for goals that are not (..., 3) (a distance over other axes is no touch's).
        """
        achieved, desired = np.asarray(achieved_goal), np.asarray(desired_goal)
        if achieved.shape[-1:] != (3,) or desired.shape[-1:] != (3,):
            raise ValueError(f"goals must be (..., 3) positions in metres, got {achieved.shape} and {desired.shape}")
        distance = np.linalg.norm(achieved - desired, axis=-1)
        if self.config.reward_type == "sparse":
            return -(distance > self.config.distance_threshold_m).astype(np.float64)
        return -1e3 * distance

    # ------------------------------------------------------------------ physics of a touch
    def _command_floats(self, position: np.ndarray, yaw: float) -> list[float] | None:
        """The joint command (6,) rad / m for the tool at ``position`` (m) and ``yaw`` (rad), by
        the compiled inverse kinematics; None if it needs the numpy path (clamped or singular)."""
        return float_paths.inverse_kinematics(kin.finite_vector(position, 3, "position"), tool_rotation(yaw), self.world.q_cmd)

    def _move(self, position: np.ndarray, yaw: float) -> MoveResult:
        """Move the tool to ``position`` (m) at ``yaw`` (rad), with noise; joints clamped into their
        limits where the pose needs it (``world.move_to`` with ``clamp_to_limits``)."""
        command = self._command_floats(position, yaw)
        if command is None:
            return self.world.move_to(tool_pose(position, yaw), noise_rng=self.np_random, clamp_to_limits=True)
        return self.world.move_joints_floats(command, noise_rng=self.np_random)

    def _true_touch_point(self) -> np.ndarray:
        """``world.true_touch_point()`` (m), compiled (``ik.touch_point_floats``'s numbers)."""
        return float_paths.touch_point(self.world.q_true, self.world.cable_constants)

    def _tip_probe(self, yaw: float) -> Callable[[np.ndarray], np.ndarray]:
        """A function from a commanded position (3,) m to where the jaws would truly be (3,) m
        if the tool were commanded there now at ``yaw`` rad, the cables' state untouched: for
        one search, during which the command and the cables' state stay as they are. Compiled
        (:func:`dvrk_gym.sim.compiled.float_paths.true_tip`) once the cables have a history."""
        world = self.world
        rotation, state = tool_rotation(yaw), world.cable.get_state()
        if math.isnan(state[0, 0]) or math.isnan(state[-1, 0]):  # no history yet: the Python float path takes numpy's
            return lambda position: self._true_tip_floats(position, rotation)
        constants, r6, roll = world.cable_constants, float_paths.wrist_yaw_rows(rotation), float(world.q_cmd[3])

        def probe(position: np.ndarray) -> np.ndarray:  # a position not finite ends in numpy's "pose must be finite"
            return float_paths.true_tip(
                position,
                r6,
                roll,
                state,
                constants=constants,
                fallback_command=lambda: ik.inverse_kinematics_clamped_floats(
                    np.asarray(position, dtype=float).tolist(), rotation, world.q_cmd
                ),
            )

        return probe

    def _true_tip_floats(self, position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """The probe's value (m) in Python floats, at the tool ``rotation`` (3, 3)."""
        cable = self.world.cable
        command = ik.inverse_kinematics_clamped_floats(kin.finite_vector(position, 3, "position").tolist(), rotation, self.world.q_cmd)
        return ik.touch_point_floats(cable.peek_true_joints_floats(command), cable.true_dh)

    def _contact_height(self, target: np.ndarray, yaw: float) -> float:
        """The commanded height of first contact: where the jaws meet the paper, or the command
        if they do not reach it (:meth:`PaperContact.command_height` says where the arm then stops).

        The true tip height moves one for one with the commanded height, so a fixed-point
        iteration finds where the jaws meet the paper in a few steps.
        """
        z, true_tip = float(target[2]), self._tip_probe(yaw)
        tip_z = true_tip(target)[2]
        if tip_z >= SURFACE_Z_M:
            return z
        for i in range(8):
            if i > 0:  # the first iteration's point is the target, just measured
                tip_z = true_tip(np.array([target[0], target[1], z]))[2]
            gap = tip_z - SURFACE_Z_M
            if abs(gap) < CONTACT_TOLERANCE_M:
                break
            z -= gap
        return z

    def _human_correction(self, circle: np.ndarray, yaw: float) -> np.ndarray:
        """The change in reported position after a person pushes the jaws onto ``circle``."""
        reported = self.world.reported_pose()[:3, 3]
        command, true_tip = reported.copy(), self._tip_probe(yaw)
        for _ in range(8):
            error = circle - true_tip(command)
            command = command + error
            if math.sqrt(error.dot(error)) < CONTACT_TOLERANCE_M:  # np.linalg.norm's own formula, without its checks
                break
        noise = self.np_random.normal(0.0, self.config.correction_noise_m, size=3)
        return command - reported + noise

    # ------------------------------------------------------------------ what is seen
    def _seen_touch_point(self, pixels: tuple[float, float, float]) -> np.ndarray:
        """The jaws' touch point as the endoscope sees it, from its exact projection ``pixels``
        (left u, v, right u; px) with pixel noise, camera frame, m."""
        noise = self.world.pixel_noise
        for _ in range(MAX_NOISE_DRAWS):  # a pair the noise crossed (no positive disparity) is no stereo match: drawn again
            left = noise.apply_floats(pixels[0], pixels[1], self.np_random)
            right = noise.apply_floats(pixels[2], pixels[1], self.np_random)  # after left's: the draw order is part of the episode
            if left[0] > right[0]:
                return np.array(self.world.camera.triangulate_floats(left, right))
        raise ValueError(f"pixel noise of {noise} left no positive disparity in {MAX_NOISE_DRAWS} draws at pixels {pixels}")

    def _desired(self, index: int) -> np.ndarray:
        return self.world.observe_grid()[index].camera_position

    def _observation(self) -> dict[str, np.ndarray]:
        reported = encode_reported(self.world.reported_pose(), self.world.jaw_angle)
        observation = np.concatenate([reported["reported_pose"], reported["jaw_angle"], [self._yaw]])
        return {
            "observation": observation.astype(np.float32),
            "achieved_goal": _clip_camera(self._achieved),
            "desired_goal": _clip_camera(self._desired(self._circle)),
        }

    def _touch_info(
        self, yaw: float, clamped: np.ndarray, joints_clamped: np.ndarray, tip: np.ndarray, tip_px: np.ndarray
    ) -> dict[str, Any]:
        """The step's info; ``tip`` is the true touch point (m) and ``tip_px`` its exact left pixel."""
        index = self._circle
        circle = self.circle_centers[index]
        circle_px = self.world.observe_grid()[index].left_uv
        pixel_offset, offset_m = tip_px - circle_px, (tip - circle)[:2]  # norms as np.linalg.norm's formula
        return {
            "circle_index": index,
            "target_yaw": self._yaw,
            "commanded_yaw": yaw,
            "pixel_error": math.sqrt(pixel_offset.dot(pixel_offset)),
            "mm_error": 1e3 * math.sqrt(offset_m.dot(offset_m)),
            "touched_paper": bool(tip[2] <= SURFACE_Z_M + TOUCH_HEIGHT_TOLERANCE_M),  # mm_error is in-plane: a hover scores too
            "true_tip_position": tip,
            "true_circle_position": circle.copy(),
            "reported_position": self.world.reported_pose()[:3, 3].copy(),
            "human_correction": self._human_correction(circle, yaw),
            "clamped": self._clamped_names(clamped, joints_clamped),
        }
