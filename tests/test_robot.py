"""The PyBullet PSM body agrees with the kinematics it is built from."""

import dataclasses

import numpy as np
import pytest

from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.body import (
    JAW_A_INDEX,
    JAW_B_INDEX,
    MARKER,
    WRIST_YAW_INDEX,
    PSMBody,
    marker_corners,
    marker_face_samples,
    marker_frame,
    marker_position,
)


@pytest.fixture
def physics():
    world = Physics()
    yield world
    world.close()


def _random_joints(rng, n):
    q = rng.uniform(kin.JOINT_LOWER, kin.JOINT_UPPER, size=(n, 6))
    q[:, 2] = rng.uniform(0.05, 0.24, size=n)
    return q


def test_wrist_yaw_frame_equals_forward_kinematics(physics):
    body = PSMBody(physics)
    for q in _random_joints(np.random.default_rng(1), 200):
        body.set_joints(q, 0.4)
        expected = kin.link_frames(q)[5]
        actual = body.wrist_yaw_frame()
        np.testing.assert_allclose(actual[:3, 3], expected[:3, 3], atol=1e-6)
        np.testing.assert_allclose(actual[:3, :3], expected[:3, :3], atol=1e-6)
        reported = kin.forward_kinematics(q)
        np.testing.assert_allclose(actual[:3, :3] @ kin.TOOL_TIP_ROTATION, reported[:3, :3], atol=1e-6)


def test_body_built_from_a_perturbed_table_follows_that_table(physics):
    dh = list(kin.PSM_DH)
    dh[3] = dataclasses.replace(dh[3], d_offset_m=dh[3].d_offset_m + 0.002)
    dh[5] = dataclasses.replace(dh[5], alpha_rad=dh[5].alpha_rad + 0.01)
    body = PSMBody(physics, dh=tuple(dh))
    q = np.array([0.2, -0.1, 0.17, 0.5, 0.3, -0.2])
    body.set_joints(q)
    np.testing.assert_allclose(body.wrist_yaw_frame(), kin.link_frames(q, tuple(dh))[5], atol=1e-6)
    assert np.linalg.norm(body.wrist_yaw_frame()[:3, 3] - kin.link_frames(q)[5][:3, 3]) > 1e-3


@pytest.mark.parametrize("jaw_deg", [0.0, 30.0, 75.0])
def test_jaw_links_reach_the_kinematic_jaw_tips(physics, jaw_deg):
    body = PSMBody(physics)
    q = np.array([0.1, 0.2, 0.16, -0.4, 0.2, 0.3])
    jaw = np.radians(jaw_deg)
    body.set_joints(q, jaw)
    tips = kin.jaw_tip_positions(q, jaw)
    for index, tip in zip((JAW_A_INDEX, JAW_B_INDEX), tips):
        frame = body.link_pose(index)
        np.testing.assert_allclose(frame[:3, 3] + frame[:3, 1] * kin.JAW_LENGTH_M, tip, atol=1e-6)


def test_negative_jaw_angle_keeps_jaws_closed(physics):
    body = PSMBody(physics)
    q = np.array([0.0, 0.0, 0.15, 0.0, 0.0, 0.0])
    body.set_joints(q, np.radians(-10))
    a, b = body.link_pose(JAW_A_INDEX), body.link_pose(JAW_B_INDEX)
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_marker_is_tape_on_the_closed_jaws_near_the_tips(physics):
    body = PSMBody(physics)
    q = np.array([0.1, 0.2, 0.16, -0.4, 0.2, 0.3])
    body.set_joints(q, 0.0)
    link = body.link_pose({"wrist_yaw": WRIST_YAW_INDEX, "wrist_pitch": 4}[MARKER.link])
    np.testing.assert_allclose(marker_frame(q), link, atol=1e-6)
    corners = marker_corners(q)
    np.testing.assert_allclose(corners.mean(axis=0), marker_position(q), atol=1e-12)
    # It marks a point near where the jaws touch, as the paper's tape did.
    assert np.linalg.norm(marker_position(q) - kin.touch_point(q)) < 0.0035


def test_marker_face_samples_only_on_faces_towards_the_viewpoint():
    q = np.array([0.0, 0.0, 0.16, 0.0, 0.0, 0.0])
    centre = marker_position(q)
    viewpoint = centre + np.array([0.0, 0.0, 0.2])  # straight above
    points, normals = marker_face_samples(q, viewpoint)
    assert len(points) in (25, 50, 75)  # one to three faces, a 5 x 5 grid each
    assert np.all(np.einsum("ij,ij->i", normals, viewpoint - points) > 0)


def test_body_holds_its_joints_when_physics_steps(physics):
    body = PSMBody(physics)
    q = np.array([0.2, -0.1, 0.17, 0.5, 0.3, -0.2])
    body.set_joints(q)
    before = body.wrist_yaw_frame()
    physics.step(240)
    np.testing.assert_allclose(body.wrist_yaw_frame()[:3, 3], before[:3, 3], atol=5e-5)
