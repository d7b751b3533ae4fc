"""The PyBullet PSM body agrees with the kinematics it is built from."""

import dataclasses

import numpy as np
import pytest

from dvrk_gym.sim import kinematics as kin
from dvrk_gym.sim.physics import Physics
from dvrk_gym.sim.robot import JAW_A_INDEX, JAW_B_INDEX, MARKER, PSMBody, marker_corners, marker_frame, marker_normal, marker_position


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


@pytest.mark.parametrize("jaw_deg", [0.0, 40.0])
def test_marker_sits_on_its_link_surface(physics, jaw_deg):
    body = PSMBody(physics)
    q = np.array([0.1, 0.2, 0.16, -0.4, 0.2, 0.3])
    jaw = np.radians(jaw_deg)
    body.set_joints(q, jaw)
    link = body.link_pose({"jaw_a": JAW_A_INDEX, "wrist_pitch": 4}[MARKER.link])
    np.testing.assert_allclose(marker_frame(q, jaw_angle_rad=jaw), link, atol=1e-6)
    centre = link[:3, :3].T @ (marker_position(q, jaw_angle_rad=jaw) - link[:3, 3])
    np.testing.assert_allclose(centre, np.add(MARKER.offset_m, np.multiply(MARKER.normal, MARKER.half_extents_m)), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(marker_normal(q, jaw_angle_rad=jaw)), 1.0)
    corners = marker_corners(q, jaw_angle_rad=jaw)
    assert corners.shape == (8, 3)
    np.testing.assert_allclose(corners.mean(axis=0), link[:3, :3] @ MARKER.offset_m + link[:3, 3], atol=1e-6)


def test_body_holds_its_joints_when_physics_steps(physics):
    body = PSMBody(physics)
    q = np.array([0.2, -0.1, 0.17, 0.5, 0.3, -0.2])
    body.set_joints(q)
    before = body.wrist_yaw_frame()
    physics.step(240)
    np.testing.assert_allclose(body.wrist_yaw_frame()[:3, 3], before[:3, 3], atol=5e-5)
