"""The simulated experiment: one PSM, its cables, the workspace and the stereo endoscope.

:class:`DvrkWorld` is what every environment wraps. It keeps the two truths of a
cable-driven robot apart:

* what the robot *reports*: ``FK_nominal(q_cmd)``, the pose its encoders imply, and
* where it *is*: ``FK(q_true, true_dh)``, after the cables have had their say
  (:mod:`dvrk_gym.sim.robot.bias`); this drives the PyBullet body, and the cameras see it.

Agents may use the reported pose and what the cameras see (pixels, triangulated
positions); the truth accessors are named ``true_*`` and are for evaluation only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import BiasConfig, CableModel, resolve_bias
from dvrk_gym.sim.endoscope.camera import PAPER_INTRINSICS, PixelWindow, StereoCamera, default_camera_pose
from dvrk_gym.sim.table.fragments import FRAGMENTS_PER_TRIAL, Fragment, FragmentType, sample_fragment_sizes, sample_layout, spawn_fragments
from dvrk_gym.sim.table.grasp import Gripper, GripperConfig
from dvrk_gym.sim.robot.motion import CartesianMove, MotionLimits, SimClock, trapezoid_progress
from dvrk_gym.sim.endoscope.detection import Blob, detect_circles, detect_marker, match_to_expected
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot.body import PSMBody, marker_corners, marker_face_samples, marker_position
from dvrk_gym.sim.physics.scene import CIRCLE_RADIUS_M, WORKSPACE_CENTER_M, SceneBodies, build_scene, grid_circle_centers

HOME_JOINTS = np.array([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
"""A retracted configuration: the tool is 34 mm below the RCM, far outside the camera's view."""

JAW_SPEED_RAD_S = math.radians(150.0)
"""How fast the jaws open or close, rad/s."""

MARKER_WINDOW_MARGIN_PX = 2
"""Pixels added around the marker's projected bounding box when rendering its window."""
MARKER_RAY_STANDOFF_M = 0.00005
"""Visibility rays stop this far in front of the marker's face, metres."""
PARKING_ORIGIN_M = np.array([0.14, -0.03, -0.175])
PARKING_PITCH_M = 0.015
"""Where fragments taken out of play are parked (on the tray, out of the paper's view), metres."""
FRAGMENT_SETTLE_STEPS = 24
"""Physics steps (0.1 s) that let new fragments settle onto the paper before a trial."""


@dataclass(frozen=True)
class WorldConfig:
    """How to build a world.

    Attributes:
        camera_resolution: (width, height) of each endoscope image in pixels; the paper's
            intrinsics are scaled to it.
        bias: the cable bias, a preset name ("none", "paper", "severe") or a BiasConfig.
        bias_seed: which instrument to draw from the bias distribution.
        gui: open the PyBullet GUI (needs a display).
        motion: the tool's speed and acceleration limits.
        camera_pose: T_base_leftcam (4x4, metres); None for the paper's set-up. Hidden
            from agents: they only see pixels.
        pixel_noise_px: standard deviation of the noise added to every detected pixel
            coordinate, at 1920 x 1080 (scaled with the resolution); models the sub-pixel
            jitter of a real endoscope's detections.
    """

    camera_resolution: tuple[int, int] = (PAPER_INTRINSICS.width, PAPER_INTRINSICS.height)
    bias: str | BiasConfig = "paper"
    bias_seed: int = 0
    gui: bool = False
    motion: MotionLimits = field(default_factory=MotionLimits)
    camera_pose: np.ndarray | None = None
    pixel_noise_px: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.pixel_noise_px) and self.pixel_noise_px >= 0):
            raise ValueError(f"pixel_noise_px must be finite and >= 0, got {self.pixel_noise_px}")
        width, height = self.camera_resolution
        if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))):
            raise ValueError(f"camera_resolution must be two ints (width, height), got {self.camera_resolution!r}")
        if not (16 <= width <= 7680 and 16 <= height <= 4320):
            raise ValueError(f"camera_resolution {self.camera_resolution} is outside 16x16 to 7680x4320 pixels")


@dataclass(frozen=True)
class StereoDetection:
    """A thing seen (or not) by both cameras.

    Attributes:
        left_uv: (u, v) in the left image, pixels; NaN when not seen.
        right_uv: (u, v) in the right image, pixels; NaN when not seen.
        camera_position: triangulated (x, y, z) in the left camera frame, metres; NaN
            unless both cameras saw it with a positive disparity.
        left_area_px: the detected region's area in the left image, pixels (0 when unseen).
        right_area_px: the same in the right image.
    """

    left_uv: np.ndarray
    right_uv: np.ndarray
    camera_position: np.ndarray
    left_area_px: float = 0.0
    right_area_px: float = 0.0

    @property
    def seen_left(self) -> bool:
        return bool(np.isfinite(self.left_uv).all())

    @property
    def seen_right(self) -> bool:
        return bool(np.isfinite(self.right_uv).all())

    @property
    def seen_both(self) -> bool:
        return bool(np.isfinite(self.camera_position).all())


@dataclass(frozen=True)
class MoveResult:
    """What one commanded move did.

    Attributes:
        duration_s: simulated seconds the move took (including settling).
        q_cmd: the commanded (and reported) joints after the move.
        q_true: the joints the cables actually produced.
        joints_clamped: which joints had to be clamped into their limits (bool, (6,)).
    """

    duration_s: float
    q_cmd: np.ndarray
    q_true: np.ndarray
    joints_clamped: np.ndarray


class DvrkWorld:
    """The PSM, its cable bias, the workspace and the stereo endoscope in one physics server.

    Args:
        config: how to build the world.
    """

    def __init__(self, config: WorldConfig | None = None) -> None:
        self.config = config or WorldConfig()
        self.bias_config = resolve_bias(self.config.bias)
        self.cable = CableModel(self.bias_config, bias_seed=self.config.bias_seed)
        width, height = self.config.camera_resolution
        self.camera = StereoCamera(
            intrinsics=PAPER_INTRINSICS.scaled(int(width), int(height)),
            pose=default_camera_pose() if self.config.camera_pose is None else self.config.camera_pose,
        )
        self.physics = Physics(gui=self.config.gui)
        self.scene: SceneBodies = build_scene(self.physics)
        self.robot = PSMBody(self.physics, dh=self.cable.true_dh)
        self.clock = SimClock()
        self.q_cmd = HOME_JOINTS.copy()
        self.q_true = HOME_JOINTS.copy()
        self.jaw_angle = 0.0
        self.fragments: list[Fragment] = []
        self.gripper: Gripper | None = None
        self._grid_cache: tuple[StereoDetection, ...] | None = None
        self.reset_robot(HOME_JOINTS)

    # ----------------------------------------------------------------- robot state
    def reset_robot(self, q: np.ndarray, jaw_angle_rad: float = 0.0) -> None:
        """Put the robot at rest at joints ``q``: cables relaxed, clock at zero."""
        q = np.array(q, dtype=float)
        self.cable.reset(q)
        self.q_cmd = q.copy()
        self.q_true = self.cable.true_joints(q)
        self.jaw_angle = float(jaw_angle_rad)
        if self.gripper is None:
            self.robot.set_joints(self.q_true, self.jaw_angle)
        else:  # nothing stays held through a reset, and the gripper drives the jaws from here
            self.gripper.release_all()
            self.gripper.place(self.q_true, self.jaw_angle)
        self.clock.reset()

    def reported_pose(self) -> np.ndarray:
        """The pose the robot reports: nominal FK of its encoders (4x4, base frame, m)."""
        return kin.forward_kinematics(self.q_cmd)

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
        jaw_angle_rad: float | None = None,
        noise_rng: np.random.Generator | None = None,
        clamp_to_limits: bool = False,
        limits: MotionLimits | None = None,
    ) -> MoveResult:
        """Move the tool frame in a straight line to ``pose`` and let it settle.

        The nominal inverse kinematics gives the joint command (what the encoders will
        report); the cable model turns it into the true joints.

        Args:
            pose: the commanded tool pose (4x4, base frame, metres).
            jaw_angle_rad: the jaw opening to end with; None keeps the current one.
            noise_rng: the generator for this move's repeatability noise (None: no noise).
            clamp_to_limits: clamp joints that would leave their limits (and report them
                in the result) instead of raising.
            limits: speed limits of this move (default: the world's).

        Raises:
            kinematics.UnreachablePoseError: if ``pose`` needs joints outside their limits
                (and ``clamp_to_limits`` is False), or is singular.
        """
        if clamp_to_limits:
            q_target, clamped = kin.inverse_kinematics_clamped(pose, q_ref=self.q_cmd)
        else:
            q_target, clamped = kin.inverse_kinematics(pose, q_ref=self.q_cmd), np.zeros(6, dtype=bool)
        move = CartesianMove.plan(self.reported_pose(), kin.forward_kinematics(q_target), limits or self.config.motion)
        return self._finish_move(q_target, move.duration_s, jaw_angle_rad, noise_rng, clamped)

    def move_joints(self, q: np.ndarray, jaw_angle_rad: float | None = None, noise_rng: np.random.Generator | None = None) -> MoveResult:
        """Command joints directly (within limits); timed as the straight move between the poses."""
        q = np.asarray(q, dtype=float)
        if not kin.within_joint_limits(q):
            raise kin.UnreachablePoseError(f"joints {np.round(q, 4).tolist()} are outside the joint limits")
        move = CartesianMove.plan(self.reported_pose(), kin.forward_kinematics(q), self.config.motion)
        return self._finish_move(q, move.duration_s, jaw_angle_rad, noise_rng, np.zeros(6, dtype=bool))

    def _finish_move(
        self,
        q_target: np.ndarray,
        duration_s: float,
        jaw_angle_rad: float | None,
        noise_rng: np.random.Generator | None,
        clamped: np.ndarray,
    ) -> MoveResult:
        jaw_time = 0.0
        if jaw_angle_rad is not None:
            jaw_time = abs(float(jaw_angle_rad) - self.jaw_angle) / JAW_SPEED_RAD_S
            self.jaw_angle = float(jaw_angle_rad)
        self.q_cmd = np.array(q_target, dtype=float)
        self.q_true = self.cable.true_joints(self.q_cmd, noise_rng)
        if self.gripper is None:
            self.robot.set_joints(self.q_true, self.jaw_angle)
        else:  # a free-space move: held fragments go along, nothing else is touched
            self.gripper.place(self.q_true, jaw_angle_rad)
            self.jaw_angle = self.gripper.jaw_angle
        elapsed = max(duration_s, jaw_time) + self.config.motion.settle_time_s
        self.clock.advance(elapsed)
        return MoveResult(elapsed, self.q_cmd.copy(), self.q_true.copy(), clamped)

    # ----------------------------------------------------------------- fragments
    def rebuild(self) -> None:
        """Empty the physics server and build the workspace and the robot again, in order.

        A reset that rebuilds gives the same physics bit for bit whatever happened before;
        removing and re-adding bodies would not (body ids, collision shapes and contact
        caches carry history). The robot ends at HOME_JOINTS with relaxed cables.
        """
        if self.gripper is not None:
            self.gripper.release_all()
        self.physics.reset()
        self.scene = build_scene(self.physics)
        self.robot = PSMBody(self.physics, dh=self.cable.true_dh)
        self.fragments, self.gripper = [], None
        self.reset_robot(HOME_JOINTS)

    def add_fragments(
        self,
        kind: str | FragmentType,
        rng: np.random.Generator,
        n: int = FRAGMENTS_PER_TRIAL,
        gripper_config: GripperConfig | None = None,
    ) -> list[Fragment]:
        """Lay ``n`` fragments of ``kind`` at random on the paper and make the jaws able to hold them.

        Sizes, positions and orientations are drawn from ``rng`` (the paper's sizes, at
        least 3 mm apart, any orientation); the fragments settle for
        FRAGMENT_SETTLE_STEPS physics steps (not counted on the clock). From now on the
        robot moves through a :class:`~dvrk_gym.sim.table.grasp.Gripper`.

        Raises:
            RuntimeError: if fragments were added since the last :meth:`rebuild`.
        """
        if self.gripper is not None:
            raise RuntimeError("this world already has fragments; call rebuild() first")
        sizes = sample_fragment_sizes(kind, rng, n)
        positions, yaws = sample_layout(rng, sizes)
        self.fragments = spawn_fragments(self.physics, kind, sizes, positions, yaws)
        self.gripper = Gripper(self.physics, self.robot, self.fragments, gripper_config)
        for _ in range(FRAGMENT_SETTLE_STEPS):
            self.gripper.step()
        return self.fragments

    def _require_gripper(self) -> Gripper:
        if self.gripper is None:
            raise RuntimeError("this world has no fragments; call add_fragments() first")
        return self.gripper

    def move_stepped(
        self,
        pose: np.ndarray,
        noise_rng: np.random.Generator | None = None,
        min_tip_clearance_m: float | None = None,
        limits: MotionLimits | None = None,
        duration_s: float | None = None,
    ) -> MoveResult:
        """Move the tool frame in a straight line to ``pose``, stepping physics all the way.

        The move is the same trapezoidal profile as :meth:`move_to`, sampled at the physics
        time step; every sample goes through the nominal inverse kinematics (the joint
        command) and the cable model (the true joints the jaws follow), so the jaws push,
        squeeze and lift what they meet. This move's repeatability noise is blended in
        along the way from the last move's.

        Args:
            pose: the commanded tool pose (4x4, base frame, metres); clamped to the
                joint limits (reported in the result).
            noise_rng: the generator for this move's repeatability noise (None: none).
            min_tip_clearance_m: keep the closed jaw tip at least this high above the
                paper: the part of the path below is raised onto that floor, where the
                tool stalls (the silicone under the paper gives; the jaws do not dig in),
                metres; None: no floor.
            limits: speed limits of this move (default: the world's).
            duration_s: make the move last exactly this long at constant speed, with
                no settling (a control period), seconds; None: the trapezoidal profile.
        """
        gripper = self._require_gripper()
        q_target, clamped = kin.inverse_kinematics_clamped(pose, q_ref=self.q_cmd)
        end = kin.forward_kinematics(q_target)
        if duration_s is None:
            move = CartesianMove.plan(self.reported_pose(), end, limits or self.config.motion)
        else:
            move = CartesianMove(self.reported_pose(), end, float(duration_s), 0.0)
        dt = self.physics.time_step_s
        offset_start = self.q_true - self.cable.true_joints(self.q_cmd)
        floor = None if min_tip_clearance_m is None else float(WORKSPACE_CENTER_M[2]) + min_tip_clearance_m
        commands, trues = [], []
        q_ref = self.q_cmd
        for waypoint in _waypoints(move, dt):
            state = self.cable.get_state()
            q_ref, _ = kin.inverse_kinematics_clamped(waypoint, q_ref=q_ref)
            q_true = self.cable.true_joints(q_ref)
            if floor is not None:
                gap = kin.touch_point(q_true + offset_start, self.cable.true_dh)[2] - floor
                if gap < 0.0:  # the tip stays on the floor: lift this waypoint by the gap (the
                    # true tip follows the command one for one in height)
                    self.cable.set_state(state)
                    waypoint = waypoint.copy()
                    waypoint[2, 3] -= gap
                    q_ref, _ = kin.inverse_kinematics_clamped(waypoint, q_ref=commands[-1] if commands else self.q_cmd)
                    q_true = self.cable.true_joints(q_ref)
            commands.append(q_ref)
            trues.append(q_true)
        noise_end = self.cable.true_joints(commands[-1], noise_rng) - trues[-1]
        fractions = np.arange(1, len(commands) + 1)[:, None] / len(commands)
        path = np.array(trues) + (1.0 - fractions) * offset_start + fractions * noise_end
        steps = gripper.follow(path)
        self.q_cmd, self.q_true = np.array(commands[-1]), path[-1].copy()
        self.jaw_angle = gripper.jaw_angle
        settle = 0.0 if duration_s is not None else self.dwell((limits or self.config.motion).settle_time_s)
        elapsed = steps * dt + settle
        self.clock.advance(steps * dt)
        return MoveResult(elapsed, self.q_cmd.copy(), self.q_true.copy(), clamped)

    def actuate_jaws(self, jaw_angle_rad: float, duration_s: float | None = None) -> float:
        """Command the jaws to an opening (rad; <= 0 closes as far as what they hold allows).

        Physics steps with the arm still, for ``duration_s`` seconds or, when None, until
        the jaws stop moving (at most 2 s). Returns the simulated seconds taken (also
        added to the clock).
        """
        gripper = self._require_gripper()
        gripper.command_jaw(jaw_angle_rad)
        dt = self.physics.time_step_s
        if duration_s is None:
            steps = gripper.settle_jaws(max_steps=int(round(2.0 / dt)))
        else:
            steps = max(0, int(round(duration_s / dt)))
            for _ in range(steps):
                gripper.step()
        self.jaw_angle = gripper.jaw_angle
        self.clock.advance(steps * dt)
        return steps * dt

    def dwell(self, seconds: float, step_physics: bool = True) -> float:
        """Wait ``seconds`` with the arm still (physics stepped, if asked); returns the time taken."""
        dt = self.physics.time_step_s
        steps = max(0, int(round(seconds / dt)))
        if step_physics and self.gripper is not None:
            for _ in range(steps):
                self.gripper.step()
        self.clock.advance(steps * dt)
        return steps * dt

    def set_aside_fragment(self, index: int) -> None:
        """Take fragment ``index`` out of play, as the operator does with a failed one.

        It is let go of (even if pierced), and parked on the tray far outside the camera's
        view of the paper, where it stays still and touches nothing.
        """
        gripper = self._require_gripper()
        fragment = self.fragments[index]
        gripper.release(fragment.name)
        c = self.physics.client
        parking = [PARKING_ORIGIN_M[0], PARKING_ORIGIN_M[1] + PARKING_PITCH_M * index, PARKING_ORIGIN_M[2]]
        c.changeDynamics(fragment.body_id, -1, mass=0.0)
        c.setCollisionFilterGroupMask(fragment.body_id, -1, 0, 0)
        c.resetBasePositionAndOrientation(fragment.body_id, parking, [0.0, 0.0, 0.0, 1.0])
        c.resetBaseVelocity(fragment.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])

    def true_fragment_positions(self) -> np.ndarray:
        """Centres of the fragments, (n, 3) base frame, metres. Evaluation only."""
        return np.array([f.position() for f in self.fragments]).reshape(-1, 3)

    # ----------------------------------------------------------------- cameras
    def render(self, side: str = "left") -> np.ndarray:
        """The full endoscope image of ``side`` ("left" or "right"), RGB uint8 (h, w, 3)."""
        return self.camera.render(self.physics.client, side)

    def observe_marker(self, noise_rng: np.random.Generator | None = None) -> StereoDetection:
        """Find the red marker in both endoscope images.

        Args:
            noise_rng: draws the configured pixel noise (None: exact detections).

        The detection runs on rendered pixels. Only the window where the marker can
        appear gets rendered: the bounding box of its corners' projections plus a margin,
        so every red pixel of a full-frame render lies inside it and the pixels there are
        the full frame's. The marker is the only red thing in the scene, so the result is
        that of a full-frame search, at a fraction of the cost.
        """
        left_uv, right_uv = self.camera.project(marker_corners(self.q_true, self.cable.true_dh))
        left = self._detect_in_window("left", left_uv)
        right = self._detect_in_window("right", right_uv)
        return self._stereo(self._with_noise(left, noise_rng), self._with_noise(right, noise_rng))

    def _with_noise(self, blob: Blob | None, noise_rng: np.random.Generator | None) -> Blob | None:
        sigma = self.config.pixel_noise_px * self.camera.intrinsics.width / PAPER_INTRINSICS.width
        if blob is None or noise_rng is None or sigma == 0.0:
            return blob
        return Blob(blob.centroid + noise_rng.normal(0.0, sigma, size=2), blob.area_px, blob.touches_border)

    def marker_visible_fraction(self, side: str) -> float:
        """Geometric visibility of the marker from one camera, without rendering.

        Rays from the camera's optical centre to a grid of points on the marker faces
        that face it; the fraction that meet nothing on the way (0: hidden, 1: seen whole).
        This is the fast geometric check; :meth:`observe_marker` is the pixel path, and
        the tests measure how the two agree.
        """
        origin = self.camera.pose[:3, 3] + (self.camera.baseline_m * self.camera.pose[:3, 0] if side == "right" else 0.0)
        points, normals = marker_face_samples(self.q_true, origin, self.cable.true_dh)
        if len(points) == 0:
            return 0.0
        # Stop each ray just in front of the face, so it cannot hit the jaws under the tape.
        ends = points + MARKER_RAY_STANDOFF_M * normals
        hits = self.physics.client.rayTestBatch([list(origin)] * len(ends), ends.tolist())
        return float(np.mean([hit[0] == -1 for hit in hits]))

    def _detect_in_window(self, side: str, corners_uv: np.ndarray) -> Blob | None:
        k = self.camera.intrinsics
        low = np.floor(corners_uv.min(axis=0)).astype(int) - MARKER_WINDOW_MARGIN_PX
        high = np.ceil(corners_uv.max(axis=0)).astype(int) + MARKER_WINDOW_MARGIN_PX
        low = np.maximum(low, 0)
        high = np.minimum(high, [k.width - 1, k.height - 1])
        if np.any(high < low):  # entirely outside the image
            return None
        window = PixelWindow(int(low[0]), int(low[1]), int(high[0] - low[0] + 1), int(high[1] - low[1] + 1))
        blob = detect_marker(self.camera.render(self.physics.client, side, window))
        if blob is None:
            return None
        return Blob(blob.centroid + [window.u0, window.v0], blob.area_px, blob.touches_border)

    def _stereo(self, left: Blob | None, right: Blob | None) -> StereoDetection:
        nan2 = np.full(2, np.nan)
        left_uv = nan2 if left is None else left.centroid
        right_uv = nan2 if right is None else right.centroid
        position = np.full(3, np.nan)
        if left is not None and right is not None and left_uv[0] - right_uv[0] > 0:
            position = self.camera.triangulate(left_uv, right_uv)[0]
        areas = [0.0 if blob is None else blob.area_px for blob in (left, right)]
        return StereoDetection(left_uv.copy(), right_uv.copy(), position, *areas)

    def observe_grid(self) -> tuple[StereoDetection, ...]:
        """Detect the 35 printed circles in both images, in grid order (row-major).

        Computed once per world with the tool retracted out of view (the grid does not
        move) from two full-frame renders, then cached. Each detection is assigned to the
        circle it belongs to by where that circle should appear, as a person reading the
        grid would; a circle that was not found gets NaN.
        """
        if self._grid_cache is None:
            self._grid_cache = self._detect_grid()
        return self._grid_cache

    def _detect_grid(self) -> tuple[StereoDetection, ...]:
        saved_q, saved_jaw = self.q_true.copy(), self.jaw_angle
        self.robot.set_joints(HOME_JOINTS, 0.0)
        k = self.camera.intrinsics
        radius_px = CIRCLE_RADIUS_M * k.fx / 0.19
        area = math.pi * radius_px**2
        expected_left, expected_right = self.camera.project(grid_circle_centers())
        found = []
        for side, expected in (("left", expected_left), ("right", expected_right)):
            detected = detect_circles(self.render(side), min_area_px=0.4 * area, max_area_px=2.0 * area)
            found.append(match_to_expected(detected, expected, max_distance_px=radius_px))
        self.robot.set_joints(saved_q, saved_jaw)
        detections = []
        for left_uv, right_uv in zip(*found):
            detections.append(self._stereo(_blob_or_none(left_uv), _blob_or_none(right_uv)))
        return tuple(detections)

    # ----------------------------------------------------------------- lifetime
    def close(self) -> None:
        """Free the physics server; safe to call more than once."""
        self.physics.close()


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


def _blob_or_none(uv: np.ndarray) -> Blob | None:
    return None if not np.isfinite(uv).all() else Blob(uv, 0.0, False)
