"""The PSM with a Large Needle Driver as a PyBullet multibody, built from a DH table.

The body's links are the frames of the modified-DH chain in :mod:`dvrk_gym.sim.kinematics`
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

from dvrk_gym.sim import kinematics as kin
from dvrk_gym.sim import meshes
from dvrk_gym.sim.physics import Physics

SHAFT_RADIUS_M = 0.0042
SHAFT_LENGTH_M = 0.25
WRIST_START_M = -0.0015
WRIST_END_M = 0.0100
"""The clevis spans x in [WRIST_START_M, WRIST_END_M] of the wrist-pitch frame: from around
the wrist-pitch pin to just past the wrist-yaw axis (at x = 9.1 mm), metres."""
WRIST_HALF_EXTENTS_M = np.array([(WRIST_END_M - WRIST_START_M) / 2, SHAFT_RADIUS_M, SHAFT_RADIUS_M])
"""Wrist-pitch link (clevis) half sizes along its frame's (x, y, z): as wide as the shaft, metres."""
SHAFT_GAP_M = 0.0020
"""The shaft ends this far above the wrist-pitch axis (the clevis turns in the gap), metres."""
JAW_THICKNESS_M = 0.0011
JAW_WIDTH_M = 0.0026


@dataclass(frozen=True)
class MarkerSpec:
    """Where the red marker (the paper's red tape) sits on the tool.

    Attributes:
        link: "jaw_a" (a jaw, moves with the jaw angle) or "wrist_pitch" (the clevis).
        offset_m: centre of the thin marker box in that link's frame, metres.
        half_extents_m: half sizes of the box in that link's frame, metres (the thin one
            along the normal).
        normal: the outward normal of its visible face in the link frame (unit, axis-aligned).
    """

    link: str
    offset_m: tuple[float, float, float]
    half_extents_m: tuple[float, float, float]
    normal: tuple[float, float, float]


MARKER = MarkerSpec(
    # Tape on one side of the clevis, between the wrist-pitch and wrist-yaw axes. Measured
    # alternatives: on a jaw's faces the jaws themselves hide all but slivers (centroid
    # errors of 10-20 px); here a 0.1 mm patch is seen whole or not at all, and under the
    # paper's rotations both cameras see it 39% of the time (the paper kept 37%).
    link="wrist_pitch",
    offset_m=(0.0060, float(WRIST_HALF_EXTENTS_M[1]) + 0.00005, 0.0),
    half_extents_m=(0.0018, 0.00005, 0.0018),
    normal=(0.0, 1.0, 0.0),
)

MARKER_RED = (0.85, 0.04, 0.04, 1.0)
SHAFT_GREY = (0.55, 0.56, 0.58, 1.0)
WRIST_GREY = (0.38, 0.38, 0.40, 1.0)
JAW_STEEL = (0.72, 0.72, 0.74, 1.0)

LINK_MASS_KG = 0.01
MOTOR_FORCE_N = 50.0

JAW_A_INDEX = 6
JAW_B_INDEX = 7
WRIST_YAW_INDEX = 5


def marker_frame(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH, jaw_angle_rad: float = 0.0, marker: MarkerSpec = MARKER) -> np.ndarray:
    """The pose (4x4, base frame, metres) of the link that carries the marker."""
    frames = kin.link_frames(q, dh)
    if marker.link == "wrist_pitch":
        return frames[4]
    half = max(jaw_angle_rad, 0.0) / 2  # jaw A turns by +jaw/2 about the wrist-yaw axis
    turn = np.eye(4)
    turn[:2, :2] = [[np.cos(half), -np.sin(half)], [np.sin(half), np.cos(half)]]
    return frames[5] @ turn


def _in_base(local: np.ndarray, frame: np.ndarray) -> np.ndarray:
    return local @ frame[:3, :3].T + frame[:3, 3]


def marker_position(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH, jaw_angle_rad: float = 0.0) -> np.ndarray:
    """Centre of the red marker's outer face for joints ``q``, base frame, metres."""
    face = np.array(MARKER.offset_m) + np.array(MARKER.normal) * np.array(MARKER.half_extents_m)
    return _in_base(face, marker_frame(q, dh, jaw_angle_rad))


def marker_corners(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH, jaw_angle_rad: float = 0.0) -> np.ndarray:
    """The 8 corners of the red marker (a thin box), (8, 3) base frame, metres.

    Its image lies inside the bounding box of these corners' projections, which is how
    the world sizes the window it renders to find the marker.
    """
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    local = np.array(MARKER.offset_m) + signs * np.array(MARKER.half_extents_m)
    return _in_base(local, marker_frame(q, dh, jaw_angle_rad))


def marker_face_points(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH, jaw_angle_rad: float = 0.0) -> np.ndarray:
    """The centre and four corners of the marker's outer face, (5, 3) base frame, metres."""
    normal = np.array(MARKER.normal)
    half = np.array(MARKER.half_extents_m)
    in_face = np.diag(half * (1 - np.abs(normal)))  # the two in-face half axes (one row is zero)
    a, b = [row for row in in_face if np.any(row)]
    centre = np.array(MARKER.offset_m) + normal * half
    local = centre + np.array([[0, 0, 0], a + b, a - b, -a + b, -a - b])
    return _in_base(local, marker_frame(q, dh, jaw_angle_rad))


def marker_normal(q: np.ndarray, dh: tuple[kin.DHRow, ...] = kin.PSM_DH, jaw_angle_rad: float = 0.0) -> np.ndarray:
    """Outward unit normal of the red marker's face for joints ``q``, base frame."""
    return marker_frame(q, dh, jaw_angle_rad)[:3, :3] @ np.array(MARKER.normal)


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
            vis = meshes.cylinder(radius, length).visual_shape(c, shapes[0].rgba, shapes[0].position, shapes[0].orientation)
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

    def set_joints(self, q: np.ndarray, jaw_angle_rad: float | None = None) -> None:
        """Place the tool at joints ``q`` (rad, insertion in m) and the given jaw opening.

        The joints are set exactly (a kinematic teleport) and the motors are told to hold
        them, so that stepping the physics does not let the arm sag.
        """
        q = np.asarray(q, dtype=float)
        if jaw_angle_rad is not None:
            self.jaw_angle = float(jaw_angle_rad)
        # Geometry cannot squeeze past closed; a negative jaw angle only adds grip force.
        half_open = max(self.jaw_angle, 0.0) / 2
        targets = list(q) + [q[5] + half_open, q[5] - half_open]
        c = self.physics.client
        for j, value in enumerate(targets):
            c.resetJointState(self.body_id, j, float(value))
        c.setJointMotorControlArray(
            self.body_id,
            list(range(len(targets))),
            c.POSITION_CONTROL,
            targetPositions=[float(v) for v in targets],
            forces=[MOTOR_FORCE_N] * len(targets),
        )
        self.joints = q.copy()

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
