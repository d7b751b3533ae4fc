"""The simulated experiment: one PSM, its cables, the workspace and the stereo endoscope.

:class:`DvrkWorld` is what every environment wraps. It keeps the two truths of a
cable-driven robot apart:

* what the robot *reports*: ``FK_nominal(q_cmd)``, the pose its encoders imply, and
* where it *is*: ``FK(q_true, true_dh)``, after the cables have had their say
  (:mod:`dvrk_gym.sim.robot.cables`); this drives the PyBullet body, and the cameras see it.

Agents may use the reported pose and what the cameras see (pixels, triangulated
positions); the truth accessors are named ``true_*`` and are for evaluation only.

The world knows nothing of what lies on the paper. A table that lays things the jaws can
hold (:class:`dvrk_gym.sim.table.table.DebridementTable`) installs itself as the world's
:class:`JawDriver`; from then on the world's moves and resets drive the tool through it.
"""

from __future__ import annotations

import dataclasses
import math
from contextlib import nullcontext

import numpy as np
import pybullet

from dvrk_gym.sim.compiled import float_paths
from dvrk_gym.sim.endoscope.baseline import PAPER_BASELINE_M, true_baseline_m
from dvrk_gym.sim.endoscope.camera import PAPER_INTRINSICS, StereoCamera, default_camera_pose
from dvrk_gym.sim.endoscope.detection import Blob, detect_marker_in_window
from dvrk_gym.sim.endoscope.noise import PixelNoise, whole_pixels
from dvrk_gym.sim.endoscope.printed_grid import observe_printed_grid
from dvrk_gym.sim.endoscope.stereo import StereoDetection, stereo_detection
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.physics.scene import PRINT_TOP_Z_M, SceneBodies, build_scene, printed_circles_hidden
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import resolve_bias
from dvrk_gym.sim.robot.body import PSMBody, marker_corners, marker_face_samples, marker_position
from dvrk_gym.sim.robot.cables import CableModel
from dvrk_gym.sim.robot.motion import CartesianMove, SimClock
from dvrk_gym.sim.robot.motion_limits import MotionLimits
from dvrk_gym.sim.world_config import JawDriver, MoveResult, WorldConfig, check_jaw_angle, check_joints, finite_joint_floats
from dvrk_gym.utils.checks import check_int

HOME_JOINTS = np.array([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
"""A retracted configuration: the tool is 34 mm below the RCM, far outside the camera's view."""
_OWN_BODIES = {field.name for field in dataclasses.fields(SceneBodies)} | {"psm"}
"""The bodies a world builds, by name (the scene registers each under its field's name)."""

JAW_SPEED_RAD_S = math.radians(150.0)
"""How fast the jaws open or close, rad/s."""

MARKER_RAY_STANDOFF_M = 0.00005
"""Visibility rays stop this far in front of the marker's face, metres."""
MARKER_CIRCLE_CLEARANCE_M = 0.0005
"""How far above the printed circles' plane the marker must be for them to be left out of its render, m."""


class DvrkWorld:
    """The PSM, its cable bias, the workspace and the stereo endoscope in one physics server.

    Args:
        config: how to build the world.

    Attributes:
        jaw_driver: what drives the tool body once something on the paper can be held
            (installed by a table, removed by :meth:`rebuild`); None: the world sets the
            body's joints itself.
    """

    def __init__(self, config: WorldConfig | None = None) -> None:
        self.config = config or WorldConfig()
        self.bias_config = resolve_bias(self.config.bias)
        self.cable = CableModel(self.bias_config, bias_seed=self.config.bias_seed)
        width, height = self.config.camera_resolution
        self.camera = StereoCamera(
            intrinsics=PAPER_INTRINSICS.scaled(int(width), int(height)),
            baseline_m=true_baseline_m(self.config.marker_noise.right_shift_px),
            pose=default_camera_pose() if self.config.camera_pose is None else self.config.camera_pose,
            calibrated_baseline_m=PAPER_BASELINE_M,
        )
        self.pixel_noise = PixelNoise(self.config.pixel_noise_px, self.camera.intrinsics.width)
        """The detection noise of every pixel the endoscope reports (scaled to this resolution)."""
        self._physics = Physics(gui=self.config.gui)
        self.scene: SceneBodies = build_scene(self._physics)
        self._robot = PSMBody(self._physics, dh=self.cable.true_dh)
        self._body_behind = False  # the body's joints wait for q_true: see the robot property
        self.clock = SimClock()
        self.q_cmd = HOME_JOINTS.copy()
        self.q_true = HOME_JOINTS.copy()
        self.jaw_angle = 0.0
        self.jaw_driver: JawDriver | None = None
        self._grid_cache: tuple[StereoDetection, ...] | None = None
        self._nominal_poses: dict[bytes, np.ndarray] = {}
        self._cable_constants: float_paths.CableConstants | None = None
        self.reset_robot(HOME_JOINTS)

    # ----------------------------------------------------------------- robot state
    def reset_robot(self, q: np.ndarray, jaw_angle_rad: float = 0.0, relax: bool = True, floats: bool = False) -> None:
        """Put the robot at rest at joints ``q``, clock at zero.

        Args:
            q: (6,) joint command, rad / m.
            jaw_angle_rad: the jaw opening, rad.
            relax: True: the cables are relaxed at ``q`` (no hysteresis gap, whatever came
                before). False: they keep their history, and the arm reaches ``q`` through
                them as a real arm sent home does (no repeatability noise: no random draw).
            floats: take the cables' float path (compiled: a few ulps from numpy's) and leave
                the body's joints to be set when asked for (no physics is stepped): GridTouch-v0's.

        Raises (before anything changes):
            ik.UnreachablePoseError: ``q`` outside the joint limits.
            ValueError: ``q`` not (6,) finite, or a jaw angle out of :func:`check_jaw_angle`'s range.
        """
        q, jaw = check_joints(q), check_jaw_angle(jaw_angle_rad)
        if relax:
            self.cable.reset(q)
        self.q_cmd = q.copy()
        self.q_true = (
            np.array(float_paths.true_joints(self.cable, self.cable_constants, q.tolist(), None)) if floats else self.cable.true_joints(q)
        )
        self.jaw_angle = jaw
        if self.jaw_driver is None:
            self._place_body(floats)
        else:  # nothing stays held through a reset
            self.jaw_driver.reset_tool(self.q_true, self.jaw_angle)
        self.clock.reset()

    @property
    def robot(self) -> PSMBody:
        """The arm's PyBullet body, its joints set to ``q_true`` first if a float-path move left them."""
        if self._body_behind:
            self._sync_body()
        return self._robot

    @property
    def physics(self) -> Physics:
        """The physics server, the arm's joints set to ``q_true`` first (as :attr:`robot`)."""
        if self._body_behind:
            self._sync_body()
        return self._physics

    def _place_body(self, floats: bool) -> None:
        """Set the body's joints to ``q_true`` and the jaw angle: now, or (``floats``: GridTouch-v0's
        path, whose physics is never stepped; not with the GUI, which shows the body) when the
        body or the physics is next asked for: renders and contacts see what they saw before."""
        self._body_behind = floats and not self.config.gui
        if not self._body_behind:
            self._robot.set_joints(self.q_true, self.jaw_angle, batched=floats)

    def restore_physics(self, state_id: int) -> None:
        """Restore the physics to a ``physics.client.saveState()``, a pending body update left pending (``q_true``
        is unchanged: the reset that follows sets the body once); ValueError if no state ``state_id`` was saved here."""
        state_id = check_int("state_id", state_id, 0)
        try:
            self._physics.client.restoreState(state_id)
        except pybullet.error:
            raise ValueError(f"no physics state {state_id} was saved in this world") from None

    def _sync_body(self) -> None:
        self._body_behind = False
        self._robot.set_joints(self.q_true, self.jaw_angle, batched=True)

    @property
    def cable_constants(self) -> float_paths.CableConstants:
        """The cable model's constants for the compiled float paths, packed on first use."""
        if self._cable_constants is None:
            self._cable_constants = float_paths.CableConstants(self.cable)
        return self._cable_constants

    def reported_pose(self) -> np.ndarray:
        """The pose the robot reports: nominal FK of its encoders (4x4, base frame, m).

        The encoders read the command unless the wrist settles short of it
        (``BiasConfig.wrist_settle_lag``; :meth:`~dvrk_gym.sim.robot.cables.CableModel.measured_joints`)."""
        return self._nominal_pose(self.cable.measured_joints(self.q_cmd)).copy()

    def _nominal_pose(self, q: np.ndarray) -> np.ndarray:
        """Nominal FK of joints ``q`` (4x4, m), remembered for the last few joint vectors:
        a move plans from the reported pose and to its end, which becomes the next
        reported pose, and observations read it again. Do not modify the result."""
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        pose = self._nominal_poses.get(key)
        if pose is None:
            if len(self._nominal_poses) >= 4:
                self._nominal_poses.clear()
            pose = self._nominal_poses[key] = kin.forward_kinematics(q)
        return pose

    def true_pose(self) -> np.ndarray:
        """Where the tool frame really is (4x4, base frame, m). For evaluation only."""
        return kin.forward_kinematics(self.q_true, self.cable.true_dh)

    def true_touch_point(self) -> np.ndarray:
        """Where the lowest point of the closed jaws really is, base frame, m. Evaluation only."""
        return kin.touch_point(self.q_true, self.cable.true_dh)

    def true_marker_position(self) -> np.ndarray:
        """Where the red marker's centre really is, base frame, m. Evaluation only."""
        return marker_position(self.q_true, self.cable.true_dh)

    def move_to(
        self,
        pose: np.ndarray,
        *,
        jaw_angle_rad: float | None = None,
        noise_rng: np.random.Generator | None = None,
        clamp_to_limits: bool = False,
        limits: MotionLimits | None = None,
    ) -> MoveResult:
        """Put the tool frame at ``pose`` and let it settle, timed as a straight-line move.

        The nominal inverse kinematics gives the joint command (what the encoders will
        report); the cable model turns it into the true joints, and the arm is placed there
        at once: no physics is stepped along the way, and the clock advances by the
        straight move's duration (trapezoidal profile) or the jaws' motion, whichever is
        longer, plus the settle time. A move that
        must meet what lies in its path is :meth:`DebridementTable.move_stepped
        <dvrk_gym.sim.table.table.DebridementTable.move_stepped>`.

        Args:
            pose: the commanded tool pose (4x4, base frame, metres).
            jaw_angle_rad: the jaw opening to end with; None keeps the current one.
            noise_rng: the generator for this move's repeatability noise (None: no noise).
            clamp_to_limits: clamp joints that would leave their limits (and report them
                in the result) instead of raising.
            limits: speed limits of this move (default: the world's).

        Raises:
            ik.UnreachablePoseError: if ``pose`` needs joints outside their limits
                (and ``clamp_to_limits`` is False), or is singular.
        """
        if clamp_to_limits:
            q_target, clamped = ik.inverse_kinematics_clamped(pose, q_ref=self.q_cmd)
        else:
            q_target, clamped = ik.inverse_kinematics(pose, q_ref=self.q_cmd), np.zeros(6, dtype=bool)
        move = CartesianMove.plan(self._nominal_pose(self.q_cmd), self._nominal_pose(q_target), limits or self.config.motion)
        return self._finish_move(q_target, move.duration_s, jaw_angle_rad, noise_rng, clamped)

    def move_joints(self, q: np.ndarray, jaw_angle_rad: float | None = None, noise_rng: np.random.Generator | None = None) -> MoveResult:
        """Command joints directly (within limits); timed as the straight move between the poses."""
        q = check_joints(q)
        move = CartesianMove.plan(self._nominal_pose(self.q_cmd), self._nominal_pose(q), self.config.motion)
        return self._finish_move(q, move.duration_s, jaw_angle_rad, noise_rng, np.zeros(6, dtype=bool))

    def move_joints_floats(self, q: list[float], noise_rng: np.random.Generator | None = None) -> MoveResult:
        """:meth:`move_joints` for joints ``q`` (6,) rad / m within the limits (as
        :func:`~dvrk_gym.sim.robot.ik.inverse_kinematics_floats` gives them; checked finite only), with
        the end pose's kinematics and the cable model on the compiled float paths: a few ulps from it."""
        q_target = finite_joint_floats(q)
        end = self._nominal_poses.get(q_target.tobytes())
        if end is None:  # for the plan only, not remembered: the reported pose stays numpy's
            end = float_paths.forward_kinematics(q)
        move = CartesianMove.plan(self._nominal_pose(self.q_cmd), end, self.config.motion)
        return self._finish_move(q_target, move.duration_s, None, noise_rng, np.zeros(6, dtype=bool), floats=q)

    def _finish_move(
        self,
        q_target: np.ndarray,
        duration_s: float,
        jaw_angle_rad: float | None,
        noise_rng: np.random.Generator | None,
        clamped: np.ndarray,
        floats: list[float] | None = None,
    ) -> MoveResult:
        """Command ``q_target`` (6,) and let the move of ``duration_s`` s settle; ``floats``: the
        same command as floats, to take the cables' float path and leave the body's joints to be
        set when asked for (GridTouch-v0's: no physics is stepped after it)."""
        jaw_time = 0.0
        if jaw_angle_rad is not None:
            jaw_angle_rad = check_jaw_angle(jaw_angle_rad)  # before anything moves
            jaw_time = abs(jaw_angle_rad - self.jaw_angle) / JAW_SPEED_RAD_S
            self.jaw_angle = jaw_angle_rad
        self.q_cmd = np.array(q_target, dtype=float)
        if floats is None:
            self.q_true = self.cable.true_joints(self.q_cmd, noise_rng)
        else:
            self.q_true = np.array(float_paths.true_joints(self.cable, self.cable_constants, floats, noise_rng))
        if self.jaw_driver is None:
            self._place_body(floats is not None)
        else:  # a free-space move: held fragments go along, nothing else is touched
            self.jaw_angle = self.jaw_driver.place_tool(self.q_true, jaw_angle_rad)
        elapsed = max(duration_s, jaw_time) + self.config.motion.settle_time_s
        self.clock.advance(elapsed)
        return MoveResult(elapsed, self.q_cmd.copy(), self.q_true.copy(), clamped)

    # ----------------------------------------------------------------- cameras
    def render(self, side: str = "left") -> np.ndarray:
        """The full endoscope image of ``side`` ("left" or "right"), RGB uint8 (h, w, 3)."""
        return self.camera.render(self.physics.client, side)

    def observe_marker(self, noise_rng: np.random.Generator | None = None) -> StereoDetection:
        """Find the red marker in both endoscope images.

        Args:
            noise_rng: draws the detector's error and the configured pixel noise, and
                the detections come in whole pixels, the right one shifted
                (``config.marker_noise.right_shift_px``), as the authors' did (None: the
                exact sub-pixel centroids of the rendered tape, no noise and no shift).

        The detection runs on rendered pixels. Only the window where the marker can
        appear gets rendered: the bounding box of its corners' projections plus a margin,
        so every red pixel of a full-frame render lies inside it and the pixels there are
        the full frame's. The marker is the only red thing in the scene, so the result is
        that of a full-frame search, at a fraction of the cost. When the marker and the
        camera are above the printed circles, the circles cannot hide any of it and are
        left out of the render (the red pixels are the same; the render is cheaper).
        """
        corners = marker_corners(self.q_true, self.cable.true_dh)
        left_uv, right_uv = self.camera.project(corners)
        above = min(corners[:, 2].min(), self.camera.pose[2, 3]) > PRINT_TOP_Z_M + MARKER_CIRCLE_CLEARANCE_M
        with printed_circles_hidden(self.physics, self.scene.grid) if above else nullcontext():
            left, right = self._detect_in_window("left", left_uv), self._detect_in_window("right", right_uv)
        left_seen = self._as_detected(left, noise_rng, "left")  # before the right one: the draws' order
        return stereo_detection(self.camera, left_seen, self._as_detected(right, noise_rng, "right"))

    def _as_detected(self, blob: Blob | None, noise_rng: np.random.Generator | None, side: str) -> Blob | None:
        """``blob`` in the ``side`` image as a real detector reports it (``blob`` itself without a
        generator): the tape detector's own misses and error (``config.marker_noise``, drawn per
        camera) and its right image's shift, the configured extra pixel noise, then whole
        pixels of the paper's 1080p grid; None outside the image's search box (after the
        draws, so the box leaves the random streams as they are)."""
        if blob is None or noise_rng is None or self.config.marker_noise.misses(noise_rng):
            return None if noise_rng is not None else blob
        width = self.camera.intrinsics.width
        noise = self.config.marker_noise
        centroid = blob.centroid + noise.sample(noise_rng, width) + noise.shift(side, width)
        centroid = whole_pixels(self.pixel_noise.apply(centroid, noise_rng), width)
        return Blob(centroid, blob.area_px, blob.touches_border) if noise.searches(side, centroid, width) else None

    def marker_visible_fraction(self, side: str) -> float:
        """Geometric visibility of the marker from one camera, without rendering: the fraction
        of rays from the camera's optical centre to a grid of points on the marker's faces
        towards it that meet nothing on the way (0: hidden, 1: seen whole). The fast check;
        :meth:`observe_marker` is the pixel path, and the tests measure how the two agree."""
        origin = self.camera.optical_centre(side)
        points, normals = marker_face_samples(self.q_true, origin, self.cable.true_dh)
        if len(points) == 0:
            return 0.0
        # Stop each ray just in front of the face, so it cannot hit the jaws under the tape.
        ends = points + MARKER_RAY_STANDOFF_M * normals
        hits = self.physics.client.rayTestBatch([list(origin)] * len(ends), ends.tolist())
        return float(np.mean([hit[0] == -1 for hit in hits]))

    def _detect_in_window(self, side: str, corners_uv: np.ndarray) -> Blob | None:
        k, client = self.camera.intrinsics, self.physics.client
        return detect_marker_in_window(lambda window: self.camera.render(client, side, window), (k.width, k.height), corners_uv)

    def observe_grid(self) -> tuple[StereoDetection, ...]:
        """Detect the 35 printed circles in both images, in grid order (row-major).

        From two full-frame renders with the tool retracted out of view (the grid does not
        move), once per world, and once per process for worlds of the same scene and
        camera (:mod:`~dvrk_gym.sim.endoscope.printed_grid`; the arrays are read-only).
        """
        if self._grid_cache is None:
            self._grid_cache = observe_printed_grid(self.camera, self._grid_scene_key(), self._render_retracted)
        return self._grid_cache

    def _grid_scene_key(self) -> tuple | None:
        """What the grid's renders depend on besides the camera, when the physics holds only
        the world's own bodies: the DH table the arm's body is built from; None (not
        cacheable) when anything else was added (a table's fragments). Reads the server's
        names without setting a pending body (a cached answer renders nothing)."""
        if set(self._physics.body_names) != _OWN_BODIES:
            return None
        return tuple(dataclasses.astuple(row) for row in self.cable.true_dh)

    def _render_retracted(self) -> tuple[np.ndarray, np.ndarray]:
        saved_q, saved_jaw = self.q_true.copy(), self.jaw_angle
        self.robot.set_joints(HOME_JOINTS, 0.0)
        try:
            return self.render("left"), self.render("right")
        finally:  # also when a render fails: the arm is not left retracted
            self.robot.set_joints(saved_q, saved_jaw)

    # ----------------------------------------------------------------- lifetime
    def rebuild(self) -> None:
        """Empty the physics server and build the workspace and the robot again, in order.

        A reset that rebuilds gives the same physics bit for bit whatever happened before;
        removing and re-adding bodies would not (body ids, collision shapes and contact
        caches carry history). The jaw driver, if any, lets go and is removed; the robot
        ends at HOME_JOINTS with relaxed cables.
        """
        if self.jaw_driver is not None:
            self.jaw_driver.detach()
            self.jaw_driver = None
        self._body_behind = False  # the body is rebuilt
        self._physics.reset()
        self.scene = build_scene(self._physics)
        self._robot = PSMBody(self._physics, dh=self.cable.true_dh)
        self.reset_robot(HOME_JOINTS)

    def close(self) -> None:
        """Free the physics server; safe to call more than once."""
        self._body_behind = False  # nothing left to set
        self._physics.close()
