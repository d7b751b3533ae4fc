"""How the jaws hold a fragment: what they touch, the tests that start a hold, the constraints.

The :class:`~dvrk_gym.sim.table.grasp.Gripper` decides when to hold and when to let go;
this module holds the pieces it decides with and acts through:

* :class:`Touch` and :func:`sense_touches`: the deepest contact of a jaw with each body;
* :func:`antipodal` (a grasp holds only an antipodal squeeze) and :func:`tip_presses_end_on`
  (a tip pierces only end-on);
* :class:`Hold` and the PyBullet constraints behind it: :func:`grasp_hold` fixes a
  squeezed fragment to the wrist, :func:`pierce_hold` pins a pierced one to a jaw tip,
  :func:`release_hold` removes either; :func:`pose_in_link` and
  :func:`restore_pose_in_link` carry a held fragment through a teleport.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.body import JAW_A_INDEX, JAW_B_INDEX, WRIST_YAW_INDEX, PSMBody
from dvrk_gym.sim.table.fragments import Fragment

JAW_LINKS = (JAW_A_INDEX, JAW_B_INDEX)
"""The two jaws' link indices in the tool body, jaw A first."""
MIN_LEVER_M = 1e-3
"""Shortest lever counted from the jaws' pivot to a grasp contact, m."""

Transform = tuple[Any, Any]
"""A PyBullet transform: (position (x, y, z) in metres, quaternion (x, y, z, w))."""


@dataclass(frozen=True)
class Touch:
    """The deepest contact of one jaw with one body (world frame, metres).

    Attributes:
        depth_m: how far the jaw presses in, m (> 0 when pressing in).
        point: the contact point on the other body, m.
        jaw_point: the contact point on the jaw, m.
        normal: the contact normal, from the other body towards the jaw.
    """

    depth_m: float
    point: np.ndarray
    jaw_point: np.ndarray
    normal: np.ndarray


@dataclass
class Hold:
    """How the jaws hold one fragment.

    Attributes:
        mode: "grasp" (squeezed between both jaws) or "pierce" (on one tip).
        constraint: the PyBullet constraint id.
        link: the robot link the fragment is attached to.
        contact_half_angles: (grasp) each jaw's half-angle when it first held the
            fragment, rad; opening past either lets go.
        levers_m: (grasp) distance from the pivot to each jaw's contact, m.
        anchor_link: (pierce) attachment point in the link's frame, m.
        anchor_fragment: (pierce) attachment point in the fragment's frame, m.
    """

    mode: str
    constraint: int
    link: int
    contact_half_angles: np.ndarray
    levers_m: np.ndarray
    anchor_link: np.ndarray
    anchor_fragment: np.ndarray


# ---------------------------------------------------------------------------- contacts
def sense_touches(client: Any, robot_id: int, link: int) -> dict[int, Touch]:
    """The deepest touch of jaw ``link`` with each other body, by body id."""
    touches: dict[int, Touch] = {}
    for cp in client.getContactPoints(bodyA=robot_id, linkIndexA=link):
        body, depth = cp[2], -cp[8]
        if body != robot_id and (body not in touches or depth > touches[body].depth_m):
            touches[body] = Touch(depth, np.array(cp[6]), np.array(cp[5]), np.array(cp[7]))
    return touches


def antipodal(fragment: Fragment, a: Touch, b: Touch, jaw_friction: float) -> bool:
    """Whether jaws touching ``fragment`` at ``a`` (jaw A) and ``b`` (jaw B) pinch its outline
    inside both friction cones.

    Tested in the fragment's own plane: the line between the two contacts must lie
    within atan(friction) of the inward normal of the outline (the ellipse of length
    and width) at each. This is what makes a seed squeezed near one end squirt out
    along its length, or one squeezed across at an angle turn out of the jaws. Out of
    that plane the test is left out: with the paper's 10 degree roll the upper jaw
    lands on a flat seed's top face, and a real seed tilts on the soft phantom until
    both jaws hold its rim, which a rigid paper cannot reproduce.
    """
    pose = fragment.pose()
    points = ((np.stack([a.point, b.point]) - pose[:3, 3]) @ pose[:3, :3])[:, :2]
    normals = points / fragment.semi_axes_m[:2] ** 2
    line = points[1] - points[0]
    lengths = np.linalg.norm(normals, axis=1)
    if np.linalg.norm(line) == 0.0 or np.any(lengths == 0.0):
        return False
    line /= np.linalg.norm(line)
    inward = -normals / lengths[:, None]
    cos_limit = math.cos(math.atan(fragment.kind.friction * jaw_friction))
    # Jaw A pushes along +line into the outline at its contact, jaw B along -line.
    return bool(line @ inward[0] >= cos_limit and -line @ inward[1] >= cos_limit)


def tip_presses_end_on(jaw_pose: np.ndarray, touch: Touch, fragment: Fragment, *, tip_zone_m: float, max_angle_rad: float) -> bool:
    """Whether a jaw (its link pose ``jaw_pose``, 4x4, m) touches ``fragment`` with its tip
    (within ``tip_zone_m`` of its end, m), pointing into the surface within ``max_angle_rad``."""
    along = jaw_pose[:3, :3].T @ (touch.jaw_point - jaw_pose[:3, 3])
    if along[1] < kin.JAW_LENGTH_M - tip_zone_m:
        return False  # pressing with the jaw's face, not its tip
    # a tip that meets the surface too obliquely slides off
    return not jaw_pose[:3, 1] @ -fragment.outward_normal(touch.point) < math.cos(max_angle_rad)


# ---------------------------------------------------------------------------- constraints
def grasp_hold(
    client: Any, robot: PSMBody, fragment: Fragment, *, jaw_points: Sequence[np.ndarray], contact_half_angles: np.ndarray, capacity_n: float
) -> Hold:
    """Hold ``fragment`` squeezed between the jaws: fixed to the wrist by a constraint that
    bears at most ``capacity_n`` N, with collisions between it and the jaws off.

    Args:
        jaw_points: where each jaw touches it (jaw A first), world frame, m.
        contact_half_angles: each jaw's half-angle where the squeeze began, rad.
    """
    levers = []
    for jaw_point, link in zip(jaw_points, JAW_LINKS):
        pivot = robot.link_pose(link)[:3, 3]
        levers.append(max(float(np.linalg.norm(jaw_point - pivot)), MIN_LEVER_M))
        client.setCollisionFilterPair(robot.body_id, fragment.body_id, link, -1, 0)
    relative = pose_in_link(client, robot.body_id, WRIST_YAW_INDEX, fragment.body_id)
    constraint = client.createConstraint(
        robot.body_id,
        WRIST_YAW_INDEX,
        fragment.body_id,
        -1,
        client.JOINT_FIXED,
        jointAxis=[0, 0, 0],
        parentFramePosition=relative[0],
        childFramePosition=[0, 0, 0],
        parentFrameOrientation=relative[1],
        childFrameOrientation=[0, 0, 0, 1],
    )
    client.changeConstraint(constraint, maxForce=capacity_n)
    return Hold("grasp", constraint, WRIST_YAW_INDEX, contact_half_angles, np.array(levers), np.zeros(3), np.zeros(3))


def pierce_hold(client: Any, robot_id: int, *, link: int, fragment: Fragment, jaw_point: np.ndarray) -> Hold:
    """Hold ``fragment`` pierced by jaw ``link`` at ``jaw_point`` (world frame, m): a point
    constraint at the tip bearing at most the fragment's ``pierce_hold_n``."""
    position, orientation = link_com(client, robot_id, link)
    inverse = client.invertTransform(position, orientation)
    anchor_link = np.array(client.multiplyTransforms(*inverse, jaw_point.tolist(), [0, 0, 0, 1])[0])
    pose = fragment.pose()
    anchor_fragment = pose[:3, :3].T @ (jaw_point - pose[:3, 3])
    constraint = client.createConstraint(
        robot_id,
        link,
        fragment.body_id,
        -1,
        client.JOINT_POINT2POINT,
        jointAxis=[0, 0, 0],
        parentFramePosition=anchor_link.tolist(),
        childFramePosition=anchor_fragment.tolist(),
    )
    client.changeConstraint(constraint, maxForce=fragment.kind.pierce_hold_n)
    client.setCollisionFilterPair(robot_id, fragment.body_id, link, -1, 0)  # the tip is inside it
    return Hold("pierce", constraint, link, np.zeros(2), np.zeros(2), anchor_link, anchor_fragment)


def pierce_stretch_m(client: Any, robot_id: int, hold: Hold, fragment: Fragment) -> float:
    """How far a pierced fragment's hole has drawn away from the tip that made it, m."""
    position, orientation = link_com(client, robot_id, hold.link)
    tip = np.array(client.multiplyTransforms(position, orientation, hold.anchor_link.tolist(), [0, 0, 0, 1])[0])
    pose = fragment.pose()
    hole = pose[:3, :3] @ hold.anchor_fragment + pose[:3, 3]
    return float(np.linalg.norm(tip - hole))


def release_hold(client: Any, robot_id: int, fragment_id: int, hold: Hold) -> None:
    """Remove a hold's constraint and let the jaws that held the fragment collide with it again."""
    client.removeConstraint(hold.constraint)
    links = JAW_LINKS if hold.mode == "grasp" else (hold.link,)
    for link in links:
        client.setCollisionFilterPair(robot_id, fragment_id, link, -1, 1)


# ---------------------------------------------------------------------------- frames
def link_com(client: Any, robot_id: int, link: int) -> tuple[list[float], list[float]]:
    """A link's centre-of-mass frame as PyBullet has it now: (position m, quaternion (x, y, z, w))."""
    state = client.getLinkState(robot_id, link, computeForwardKinematics=True)
    return list(state[0]), list(state[1])


def pose_in_link(client: Any, robot_id: int, link: int, body: int) -> Transform:
    """Where ``body`` is in ``link``'s centre-of-mass frame."""
    position, orientation = link_com(client, robot_id, link)
    return client.multiplyTransforms(*client.invertTransform(position, orientation), *client.getBasePositionAndOrientation(body))


def restore_pose_in_link(client: Any, robot_id: int, *, link: int, body: int, relative: Transform) -> None:
    """Put ``body`` back at ``relative`` in ``link``'s frame (from :func:`pose_in_link`), at rest."""
    position, orientation = link_com(client, robot_id, link)
    world = client.multiplyTransforms(position, orientation, *relative)
    client.resetBasePositionAndOrientation(body, world[0], world[1])
    client.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0])
