"""The PSM with a Large Needle Driver as a PyBullet multibody, built from a DH table.

The body's links are the frames of the modified-DH chain in :mod:`dvrk_gym.sim.robot.kinematics`
(its joint i is pybullet joint i - 1), so the wrist-yaw link frame equals
``link_frames(q, dh)[5]`` for the same table. Only the tool is drawn: the 8 mm shaft
(through the remote centre of motion), the wrist, two 10 mm jaws, and a red marker (the
paper's red tape) on one face of the wrist-pitch link, which the wrist itself hides from
the cameras at some orientations. The remote-centre mechanism above is not modelled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_gym.sim import identified
from dvrk_gym.sim.physics import meshes
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot import kinematics as kin

SHAFT_RADIUS_M = 0.0042
SHAFT_LENGTH_M = 0.25
WRIST_START_M = -0.0015
WRIST_END_M = 0.0091
"""The clevis spans x in [WRIST_START_M, WRIST_END_M] of the wrist-pitch frame: from around
the wrist-pitch pin to the wrist-yaw axis, where the jaws pivot, metres."""
WRIST_HALF_EXTENTS_M = np.array([(WRIST_END_M - WRIST_START_M) / 2, 0.0026, 0.0032])
"""Wrist-pitch link (clevis) half sizes along its frame's (x, y, z), metres: 5.2 x 6.4 mm,
narrower than the 8.4 mm shaft, as on the Large Needle Driver."""
SHAFT_GAP_M = 0.0020
"""The shaft ends this far above the wrist-pitch axis (the clevis turns in the gap), metres."""
JAW_THICKNESS_M = 0.0011
JAW_WIDTH_M = 0.0026


@dataclass(frozen=True)
class MarkerSpec:
    """Where the red marker (the paper's red tape) sits on the tool: a small box.

    Attributes:
        link: "wrist_yaw" (the jaws' pivot frame; the jaws are closed when it is tracked)
            or "wrist_pitch" (the clevis).
        offset_m: centre of the box in that link's frame, metres.
        half_extents_m: half sizes of the box along that frame's axes, metres.
    """

    link: str
    offset_m: tuple[float, float, float]
    half_extents_m: tuple[float, float, float]


MARKER = MarkerSpec(
    # The paper's red tape: a 3 mm strip folded over jaw B's outer edge (its +x side and
    # the lower half of its -z side), centred where the identification from the authors'
    # rows puts the tape along the jaws (dvrk_gym.sim.identified.MARKER_OFFSET_M: 8.0 mm
    # from the pivot; the tips are at 10 mm). The camera looks at the jaws nearly end-on
    # from above the wrist, so it sees the strip at a grazing angle, and the wrist and
    # the shaft hide it at some orientations. Which sides the tape covers decides which
    # orientations keep their rows. Measured over the paper's rotations (500 random
    # poses, identified instrument and detector, no misses), the kept rows fall on the
    # paper's yaws -90 .. 90 as .15 .33 .26 .20 .07 with pitches -13 to 21 degrees (5th-95th
    # percentile); the real rows: .13 .30 .28 .20 .09 and -11 to 21. Dropped: tape on the
    # -z side only (.03 .19 .34 .27 .17, pitches up to 8 degrees), on the +x side only
    # (.18 .39 .26 .14 .03), a band round both jaws (.14 .30 .29 .19 .08, but its centroid
    # wanders 5 px with the view, twice as far as this strip's).
    link="wrist_yaw",
    offset_m=(JAW_THICKNESS_M / 2 + 0.000025, identified.MARKER_OFFSET_M[1], -(JAW_WIDTH_M / 4 + 0.000025)),
    half_extents_m=(JAW_THICKNESS_M / 2 + 0.000075, 0.0015, JAW_WIDTH_M / 4 + 0.000025),
)

MARKER_RED = (0.85, 0.04, 0.04, 1.0)
SHAFT_GREY = (0.55, 0.56, 0.58, 1.0)
WRIST_GREY = (0.38, 0.38, 0.40, 1.0)
JAW_STEEL = (0.72, 0.72, 0.74, 1.0)

LINK_MASS_KG = 0.01
MOTOR_FORCE_N = 50.0
"""Force (N, or N m) of the motors that hold each joint, or carry it through a step."""
JAW_FRICTION = 1.0
"""Friction coefficient of the jaws (PyBullet multiplies it with the other body's, so 1
leaves a fragment's own friction in force)."""

JAW_A_INDEX = 6
JAW_B_INDEX = 7
_JOINT_INDICES = list(range(JAW_B_INDEX + 1))
"""Every joint of the body: the six arm joints, then jaw A and jaw B."""
WRIST_YAW_INDEX = 5


def marker_frame(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH) -> np.ndarray:
    """The pose (4x4, base frame, metres) of the link that carries the marker."""
    return kin.link_frames(q, dh)[5 if MARKER.link == "wrist_yaw" else 4]


def _in_base(local: np.ndarray, frame: np.ndarray) -> np.ndarray:
    return local @ frame[:3, :3].T + frame[:3, 3]


def marker_position(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH) -> np.ndarray:
    """Centre of the red marker for joints ``q``, base frame, metres."""
    return _in_base(np.array(MARKER.offset_m), marker_frame(q, dh))


def marker_corners(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH) -> np.ndarray:
    """The 8 corners of the red marker box, (8, 3) base frame, metres.

    Its image lies inside the bounding box of these corners' projections, which is how
    the world sizes the window it renders to find the marker.
    """
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return _in_base(np.array(MARKER.offset_m) + signs * np.array(MARKER.half_extents_m), marker_frame(q, dh))


def marker_face_samples(q: np.ndarray, viewpoint: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH) -> tuple[np.ndarray, np.ndarray]:
    """Points on the marker's faces that face ``viewpoint``, and those faces' normals.

    A 5 x 5 grid on every face whose outward normal points towards the viewpoint (base
    frame, metres).

    Returns:
        (points (N, 3), normals (N, 3)), base frame.
    """
    frame = marker_frame(q, dh)
    centre = np.array(MARKER.offset_m)
    half = np.array(MARKER.half_extents_m)
    view_local = frame[:3, :3].T @ (np.asarray(viewpoint, dtype=float) - frame[:3, 3])
    points, normals = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            face_centre = centre + normal * half
            if normal @ (view_local - face_centre) <= 0.0:
                continue
            u, v = [np.eye(3)[i] * half[i] for i in range(3) if i != axis]
            steps = np.linspace(-1.0, 1.0, 5)
            grid = [face_centre + a * u + b * v for a in steps for b in steps]
            points += grid
            normals += [normal] * len(grid)
    if not points:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return _in_base(np.array(points), frame), np.array(normals) @ frame[:3, :3].T


@dataclass(frozen=True)
class _Shape:
    """One box or cylinder of a link, in the link frame (metres)."""

    kind: str  # "box" or "cylinder" (cylinder axis along the shape's own z)
    size: tuple[float, ...]  # half extents for a box; (radius, length) for a cylinder
    position: tuple[float, float, float]
    rgba: tuple[float, float, float, float]
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    collides: bool = True


def _link_shapes() -> dict[str, list[_Shape]]:
    """The drawn geometry of each link, keyed by link name (cylinders along link z)."""
    wx, wy, wz = (float(v) for v in WRIST_HALF_EXTENTS_M)
    jaw_x = JAW_THICKNESS_M / 2
    jaw_len = kin.JAW_LENGTH_M
    shapes = {
        "roll": [
            # The shaft rolls with the roll joint; it ends just above the wrist-pitch axis.
            _Shape("cylinder", (SHAFT_RADIUS_M, SHAFT_LENGTH_M), (0.0, 0.0, -SHAFT_GAP_M - SHAFT_LENGTH_M / 2), SHAFT_GREY),
        ],
        "wrist_pitch": [
            _Shape("box", (wx, wy, wz), (WRIST_START_M + wx, 0.0, 0.0), WRIST_GREY),
        ],
        "jaw_a": [  # jaw A opens towards -x (its angle is q6 + jaw / 2): it sits on the -x side
            _Shape("box", (jaw_x, jaw_len / 2, JAW_WIDTH_M / 2), (-jaw_x, jaw_len / 2, 0.0), JAW_STEEL),
        ],
        "jaw_b": [
            _Shape("box", (jaw_x, jaw_len / 2, JAW_WIDTH_M / 2), (jaw_x, jaw_len / 2, 0.0), JAW_STEEL),
        ],
        "wrist_yaw": [  # the jaw pivot pin, along the wrist-yaw axis
            _Shape("box", (0.0011, 0.0011, JAW_WIDTH_M), (0.0, 0.0, 0.0), WRIST_GREY, collides=False),
        ],
    }
    shapes[MARKER.link].append(_Shape("box", MARKER.half_extents_m, MARKER.offset_m, MARKER_RED, collides=False))
    return shapes


def _pose_to_pybullet(t: np.ndarray) -> tuple[list[float], list[float]]:
    return [float(v) for v in t[:3, 3]], [float(v) for v in Rotation.from_matrix(t[:3, :3]).as_quat()]


class PSMBody:
    """The simulated PSM tool in a physics server, driven to joint angles.

    Args:
        physics: the world to build the body in.
        dh: the DH table the body is built from (the *true* instrument; a bias model may
            pass a perturbed table).
        name: the body's name in ``physics``.
    """

    def __init__(self, physics: Physics, dh: tuple[kin.DHRow, ...] = kin.PSM_DH, name: str = "psm") -> None:
        self.physics = physics
        self.dh = tuple(dh)
        self.name = name
        self.body_id = physics.add(name, self._build())
        for link in (JAW_A_INDEX, JAW_B_INDEX):
            physics.client.changeDynamics(self.body_id, link, lateralFriction=JAW_FRICTION)
        self.joints = np.array([0.0, 0.0, 0.12, 0.0, 0.0, 0.0])
        self.jaw_angle = 0.0
        self.set_joints(self.joints, 0.0)

    def _shape_ids(self, shapes: list[_Shape]) -> tuple[int, int]:
        c = self.physics.client
        if not shapes:
            return -1, -1

        def kwargs(subset: list[_Shape]) -> dict:
            return dict(
                shapeTypes=[c.GEOM_BOX if s.kind == "box" else c.GEOM_CYLINDER for s in subset],
                halfExtents=[list(s.size) if s.kind == "box" else [0.0, 0.0, 0.0] for s in subset],
                radii=[s.size[0] if s.kind == "cylinder" else 0.0 for s in subset],
                lengths=[s.size[1] if s.kind == "cylinder" else 0.0 for s in subset],
            )

        if len(shapes) == 1 and shapes[0].kind == "cylinder":  # pybullet draws cylinders too wide
            radius, length = shapes[0].size
            vis = self.physics.mesh_visual(meshes.cylinder(radius, length), shapes[0].rgba, shapes[0].position, shapes[0].orientation)
        else:
            vis = c.createVisualShapeArray(
                **kwargs(shapes),
                rgbaColors=[list(s.rgba) for s in shapes],
                visualFramePositions=[list(s.position) for s in shapes],
                visualFrameOrientations=[list(s.orientation) for s in shapes],
            )
        colliding = [s for s in shapes if s.collides]
        col = -1
        if colliding:
            col = c.createCollisionShapeArray(
                **kwargs(colliding),
                collisionFramePositions=[list(s.position) for s in colliding],
                collisionFrameOrientations=[list(s.orientation) for s in colliding],
            )
        return col, vis

    def _build(self) -> int:
        c = self.physics.client
        shapes = _link_shapes()
        names = list(kin.JOINT_NAMES) + ["jaw_a", "jaw_b"]
        parents = [0, 1, 2, 3, 4, 5, 5, 5]  # pybullet: 0 is the base, k is link k - 1
        # A joint adds q on top of its DH row's constant part, so the parent frame is the
        # row at q = 0; the jaws pivot on the wrist-yaw axis like the wrist-yaw frame.
        frames = [kin.dh_transform(row, 0.0) for row in self.dh]
        frames += [frames[5], frames[5]]
        types = [c.JOINT_PRISMATIC if row.prismatic else c.JOINT_REVOLUTE for row in self.dh]
        types += [c.JOINT_REVOLUTE, c.JOINT_REVOLUTE]
        cols, viss, positions, orientations = [], [], [], []
        for name, frame in zip(names, frames):
            col, vis = self._shape_ids(shapes.get(name, []))
            cols.append(col)
            viss.append(vis)
            pos, orn = _pose_to_pybullet(frame)
            positions.append(pos)
            orientations.append(orn)
        n = len(names)
        return c.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=-1,
            baseVisualShapeIndex=-1,
            basePosition=[0.0, 0.0, 0.0],
            linkMasses=[LINK_MASS_KG] * n,
            linkCollisionShapeIndices=cols,
            linkVisualShapeIndices=viss,
            linkPositions=positions,
            linkOrientations=orientations,
            linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n,
            linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
            linkParentIndices=parents,
            linkJointTypes=types,
            linkJointAxis=[[0.0, 0.0, 1.0]] * n,
            useMaximalCoordinates=False,
        )

    def set_joints(self, q: np.ndarray, jaw_angle_rad: float | None = None, batched: bool = False) -> None:
        """Place the tool at joints ``q`` (rad, insertion in m) and the given jaw opening.

        The joints are set exactly (a kinematic teleport) and the motors are told to hold
        them, so that stepping the physics does not let the arm sag. ``batched``: set all
        joints in one PyBullet call, a fifth of the time of one call per joint; the same
        joint state, but physics stepped afterwards can differ (PyBullet's collision
        bookkeeping sees the joints set in another order: a debridement pick moved a
        fragment by 0.04 mm), so only for a world whose physics is never stepped.
        """
        q = np.asarray(q, dtype=float)
        if jaw_angle_rad is not None:
            self.jaw_angle = float(jaw_angle_rad)
        # Geometry cannot squeeze past closed; a negative jaw angle only adds grip force.
        half_open = max(self.jaw_angle, 0.0) / 2
        joints = q.tolist()
        positions = joints + [joints[5] + half_open, joints[5] - half_open]
        c = self.physics.client
        if batched:
            c.resetJointStatesMultiDof(self.body_id, _JOINT_INDICES, [[v] for v in positions])
        else:
            for j, value in enumerate(positions):
                c.resetJointState(self.body_id, j, value)
        self._drive_motors(c.POSITION_CONTROL, len(positions), targetPositions=positions)
        self.joints = q.copy()

    def drive(
        self,
        q: np.ndarray,
        jaw_half_angles: np.ndarray,
        arm_velocity: np.ndarray,
        jaw_rates: np.ndarray,
    ) -> None:
        """Set every joint where it is now, with the velocity it keeps over the next step.

        For stepping physics with a moving tool (contacts see a moving jaw): each joint is
        reset to its position and velocity, and a velocity motor of MOTOR_FORCE_N carries
        that velocity through the step. Unlike :meth:`set_joints`, the jaws open
        independently.

        Args:
            q: (6,) arm joints now, rad / m.
            jaw_half_angles: (2,) how far jaw A and jaw B are open from the closed
                position, rad (>= 0).
            arm_velocity: (6,) arm joint velocities for the step, rad/s / m/s.
            jaw_rates: (2,) opening rates of jaw A and jaw B, rad/s (+ opens).
        """
        q = np.asarray(q, dtype=float)
        arm_velocity = np.asarray(arm_velocity, dtype=float)
        positions = list(q) + [q[5] + jaw_half_angles[0], q[5] - jaw_half_angles[1]]
        velocities = list(arm_velocity) + [arm_velocity[5] + jaw_rates[0], arm_velocity[5] - jaw_rates[1]]
        c = self.physics.client
        for j, (p, v) in enumerate(zip(positions, velocities)):
            c.resetJointState(self.body_id, j, float(p), float(v))
        self._drive_motors(c.VELOCITY_CONTROL, len(positions), targetVelocities=[float(v) for v in velocities])
        self.joints = q.copy()
        self.jaw_angle = float(jaw_half_angles[0] + jaw_half_angles[1])

    def _drive_motors(self, mode: int, n_joints: int, **targets: list[float]) -> None:
        """Motors of MOTOR_FORCE_N on joints 0..n_joints-1 in PyBullet control mode ``mode``, toward ``targets``."""
        joints = list(range(n_joints))
        self.physics.client.setJointMotorControlArray(self.body_id, joints, mode, forces=[MOTOR_FORCE_N] * n_joints, **targets)

    def link_pose(self, link_index: int) -> np.ndarray:
        """The world pose (4x4, metres) of a link's frame as PyBullet has it now."""
        state = self.physics.client.getLinkState(self.body_id, link_index, computeForwardKinematics=True)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat(state[5]).as_matrix()
        pose[:3, 3] = state[4]
        return pose

    def wrist_yaw_frame(self) -> np.ndarray:
        """The wrist-yaw frame (DH frame 6, without the tool-tip rotation) as simulated."""
        return self.link_pose(WRIST_YAW_INDEX)
