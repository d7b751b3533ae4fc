"""Tests for dvrk_gym.sim.robot.kinematics and .ik (PSM forward/inverse kinematics and helpers)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin

ZERO_Q = np.array([0.0, 0.0, 0.18, 0.0, 0.0, 0.0])
# Hand-derived: tool x = base y, tool y = base x, tool z = -base z.
ZERO_POSE_ROTATION = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
# RCM -> wrist yaw pivot along the shaft at zero wrist: insertion - 0.4318 + 0.4162 + 0.0091.
SHAFT_TO_PIVOT_M = -0.0065


def _rot_x(a: float) -> np.ndarray:
    return Rotation.from_euler("x", a).as_matrix()


def _rot_y(a: float) -> np.ndarray:
    return Rotation.from_euler("y", a).as_matrix()


def _rot_z(a: float) -> np.ndarray:
    return Rotation.from_euler("z", a).as_matrix()


def _random_q(rng: np.random.Generator, n: int, insertion_range: tuple[float, float]) -> np.ndarray:
    shrink = 1e-6
    q = rng.uniform(kin.JOINT_LOWER + shrink, kin.JOINT_UPPER - shrink, size=(n, 6))
    q[:, 2] = rng.uniform(*insertion_range, size=n)
    return q


def _wrapped(angle: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(angle)))


# --- forward kinematics -------------------------------------------------------------


def test_zero_pose_is_173_5_mm_below_rcm_with_tool_z_pointing_down() -> None:
    pose = kin.forward_kinematics(ZERO_Q)
    np.testing.assert_allclose(pose[:3, 3], [0.0, 0.0, -0.1735], atol=1e-12)
    np.testing.assert_allclose(pose[:3, :3], ZERO_POSE_ROTATION, atol=1e-12)
    np.testing.assert_allclose(pose[3], [0, 0, 0, 1])


@pytest.mark.parametrize("yaw", [-1.2, -0.3, 0.4, 1.5])
def test_outer_yaw_swings_tip_in_xz_plane_on_sphere_about_rcm(yaw: float) -> None:
    q = ZERO_Q.copy()
    q[0] = yaw
    pose = kin.forward_kinematics(q)
    radius = ZERO_Q[2] + SHAFT_TO_PIVOT_M
    expected = [radius * np.sin(yaw), 0.0, -radius * np.cos(yaw)]
    np.testing.assert_allclose(pose[:3, 3], expected, atol=1e-12)
    # Positive yaw is a rotation of -yaw about base y.
    np.testing.assert_allclose(pose[:3, :3], _rot_y(-yaw) @ ZERO_POSE_ROTATION, atol=1e-12)


@pytest.mark.parametrize("pitch", [-0.9, -0.2, 0.3, 0.9])
def test_outer_pitch_swings_tip_toward_negative_y(pitch: float) -> None:
    q = ZERO_Q.copy()
    q[1] = pitch
    pose = kin.forward_kinematics(q)
    radius = ZERO_Q[2] + SHAFT_TO_PIVOT_M
    expected = [0.0, -radius * np.sin(pitch), -radius * np.cos(pitch)]
    np.testing.assert_allclose(pose[:3, 3], expected, atol=1e-12)
    np.testing.assert_allclose(pose[:3, :3], _rot_x(-pitch) @ ZERO_POSE_ROTATION, atol=1e-12)


def test_insertion_moves_tip_along_shaft_without_rotating() -> None:
    q = np.array([0.5, -0.3, 0.10, 0.7, 0.2, -0.4])
    deeper = q.copy()
    deeper[2] += 0.05
    shaft = kin.link_frames(q)[3][:3, 2]
    # shaft = (sin(yaw) cos(pitch), -sin(pitch), -cos(yaw) cos(pitch))
    expected = [np.sin(0.5) * np.cos(0.3), np.sin(0.3), -np.cos(0.5) * np.cos(0.3)]
    np.testing.assert_allclose(shaft, expected, atol=1e-12)
    before, after = kin.forward_kinematics(q), kin.forward_kinematics(deeper)
    np.testing.assert_allclose(after[:3, 3] - before[:3, 3], 0.05 * shaft, atol=1e-12)
    np.testing.assert_allclose(after[:3, :3], before[:3, :3], atol=1e-12)


def test_roll_spins_tool_about_shaft_without_moving_tip() -> None:
    q = ZERO_Q.copy()
    q[3] = 0.8
    pose = kin.forward_kinematics(q)
    np.testing.assert_allclose(pose[:3, 3], [0.0, 0.0, -0.1735], atol=1e-12)
    # The shaft points along -z, so a positive roll is a rotation of -roll about base z.
    np.testing.assert_allclose(pose[:3, :3], _rot_z(-0.8) @ ZERO_POSE_ROTATION, atol=1e-12)


def test_dh_transform_is_craig_product() -> None:
    row = kin.DHRow(alpha_rad=0.3, a_m=0.02, theta_offset_rad=-0.4, d_offset_m=0.05, prismatic=False)
    expected = np.eye(4)
    expected[:3, :3] = _rot_x(0.3) @ _rot_z(-0.4 + 0.2)
    expected[:3, 3] = _rot_x(0.3) @ (np.array([0.02, 0.0, 0.0]) + _rot_z(-0.2) @ [0.0, 0.0, 0.05])
    np.testing.assert_allclose(kin.dh_transform(row, 0.2), expected, atol=1e-15)
    prismatic = dataclasses.replace(row, prismatic=True)
    np.testing.assert_allclose(kin.dh_transform(prismatic, 0.01)[:3, 3], _rot_x(0.3) @ [0.02, 0.0, 0.06], atol=1e-15)


def test_link_frames_end_in_fk_pose_without_tool_tip_rotation() -> None:
    q = np.array([0.2, 0.1, 0.15, -1.0, 0.5, 0.3])
    frames = kin.link_frames(q)
    assert frames.shape == (6, 4, 4)
    expected = frames[-1].copy()
    expected[:3, :3] = expected[:3, :3] @ kin.TOOL_TIP_ROTATION
    np.testing.assert_allclose(kin.forward_kinematics(q), expected, atol=1e-15)


def test_perturbed_dh_table_changes_fk_and_copy_does_not() -> None:
    q = np.array([0.2, 0.1, 0.15, -1.0, 0.5, 0.3])
    nominal = kin.forward_kinematics(q)
    perturbed = list(kin.PSM_DH)
    perturbed[5] = dataclasses.replace(perturbed[5], a_m=perturbed[5].a_m + 0.001)
    perturbed[2] = dataclasses.replace(perturbed[2], alpha_rad=perturbed[2].alpha_rad + 0.01)
    biased = kin.forward_kinematics(q, tuple(perturbed))
    assert np.linalg.norm(biased[:3, 3] - nominal[:3, 3]) > 5e-4
    np.testing.assert_allclose(kin.forward_kinematics(q, tuple(kin.PSM_DH)), nominal, atol=0)


# --- inverse kinematics -------------------------------------------------------------


def test_ik_round_trip_recovers_joints_and_pose_for_1000_random_configurations() -> None:
    rng = np.random.default_rng(1234)
    for q in _random_q(rng, 1000, (0.05, 0.24)):
        pose = kin.forward_kinematics(q)
        q_free = ik.inverse_kinematics(pose)
        q_ref = ik.inverse_kinematics(pose, q_ref=q)
        np.testing.assert_allclose(q_ref, q, atol=1e-9, rtol=0)
        np.testing.assert_allclose(np.delete(q_free, 3), np.delete(q, 3), atol=1e-9, rtol=0)
        assert abs(_wrapped(q_free[3] - q[3])) < 1e-9
        assert -np.pi < q_free[3] <= np.pi
        np.testing.assert_allclose(kin.forward_kinematics(q_free), pose, atol=1e-9, rtol=0)


def test_ik_round_trip_with_shallow_insertion_below_wrist_offset() -> None:
    # With insertion < 15.6 mm the wrist-pitch point sits above the RCM (other IK branches).
    rng = np.random.default_rng(99)
    for q in _random_q(rng, 300, (0.0, 0.05)):
        pose = kin.forward_kinematics(q)
        q_ik = ik.inverse_kinematics(pose, q_ref=q)
        np.testing.assert_allclose(kin.forward_kinematics(q_ik), pose, atol=1e-9, rtol=0)
        np.testing.assert_allclose(q_ik, q, atol=1e-9, rtol=0)


def test_ik_picks_roll_branch_nearest_reference() -> None:
    q = np.array([0.1, -0.2, 0.15, np.deg2rad(250.0), 0.3, -0.2])
    pose = kin.forward_kinematics(q)
    assert ik.inverse_kinematics(pose)[3] == pytest.approx(np.deg2rad(-110.0), abs=1e-9)
    near = ik.inverse_kinematics(pose, q_ref=np.r_[0, 0, 0.1, 4.0, 0, 0])
    assert near[3] == pytest.approx(q[3], abs=1e-9)
    # A reference beyond the limit still yields a roll within +-260 deg.
    far = ik.inverse_kinematics(pose, q_ref=np.r_[0, 0, 0.1, 20.0, 0, 0])
    assert far[3] == pytest.approx(q[3], abs=1e-9)


def test_ik_reaches_paper_typical_orientation() -> None:
    pose = kin.pose_from_euler([0.04, 0.04, -0.164], 0.0, np.deg2rad(5.0), np.deg2rad(-167.0))
    q = ik.inverse_kinematics(pose)
    assert kin.within_joint_limits(q)
    np.testing.assert_allclose(kin.forward_kinematics(q), pose, atol=1e-12)


def test_ik_raises_with_joint_name_and_degrees_for_target_above_rcm() -> None:
    pose = kin.pose_from_euler([0.0, 0.0, 0.05], 0.0, 0.0, np.pi)
    message = r"outer_yaw = 180\.000 deg is outside \[-91\.000, 91\.000\] deg"
    with pytest.raises(ik.UnreachablePoseError, match=message):
        ik.inverse_kinematics(pose)


def test_ik_raises_with_millimetres_for_too_deep_target() -> None:
    pose = kin.forward_kinematics(ZERO_Q)
    pose[2, 3] = -0.30
    message = r"insertion = 306\.500 mm is outside \[0\.000, 240\.000\] mm"
    with pytest.raises(ik.UnreachablePoseError, match=message):
        ik.inverse_kinematics(pose)


def test_ik_raises_for_outer_pitch_beyond_limit() -> None:
    q = np.array([0.0, np.deg2rad(60.0), 0.15, 0.0, 0.0, 0.0])
    with pytest.raises(ik.UnreachablePoseError, match="outer_pitch = 60.000 deg"):
        ik.inverse_kinematics(kin.forward_kinematics(q))


def test_ik_raises_geometric_error_for_target_at_rcm() -> None:
    pose = kin.pose_from_euler([0.0, 0.0, 0.0], 0.0, 0.0, np.pi)
    with pytest.raises(ik.UnreachablePoseError, match="too close to the RCM"):
        ik.inverse_kinematics(pose)


def test_ik_raises_geometric_error_for_wrist_pitch_point_at_rcm() -> None:
    # Tool pitched 90 deg so the wrist-yaw axis is base z, the pivot one wrist offset
    # along base x: the wrist-pitch point falls on the RCM.
    pose = kin.pose_from_euler([kin.PSM_DH[5].a_m, 0.0, 0.0], 0.0, np.pi / 2, 0.0)
    with pytest.raises(ik.UnreachablePoseError, match="wrist-pitch point is 0.0000 mm from the RCM"):
        ik.inverse_kinematics(pose)


@pytest.mark.parametrize(
    "pose",
    [
        np.full((4, 4), np.nan),
        np.eye(3),
        np.diag([1.0, 1.0, -1.0, 1.0]),
        np.diag([2.0, 1.0, 1.0, 1.0]),
    ],
    ids=["nan", "wrong-shape", "reflection", "not-orthonormal"],
)
def test_ik_rejects_malformed_pose_with_plain_value_error(pose: np.ndarray) -> None:
    with pytest.raises(ValueError) as info:
        ik.inverse_kinematics(pose)
    assert not isinstance(info.value, ik.UnreachablePoseError)


def test_fk_rejects_nan_and_wrong_length() -> None:
    with pytest.raises(ValueError, match="finite"):
        kin.forward_kinematics([0, 0, np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match="shape"):
        kin.forward_kinematics([0, 0, 0.1])


# --- joint limits ---------------------------------------------------------------------


def test_clamp_reports_exactly_the_clamped_joints() -> None:
    q = np.array([np.deg2rad(100.0), 0.0, -0.01, np.deg2rad(-300.0), 0.1, np.deg2rad(80.0)])
    clamped, mask = kin.clamp_to_joint_limits(q)
    np.testing.assert_array_equal(mask, [True, False, True, True, False, False])
    expected = [np.deg2rad(91.0), 0.0, 0.0, np.deg2rad(-260.0), 0.1, np.deg2rad(80.0)]
    np.testing.assert_allclose(clamped, expected)
    assert kin.within_joint_limits(clamped)
    assert not kin.within_joint_limits(q)


def test_joint_limit_constants_are_in_si_units_and_read_only() -> None:
    np.testing.assert_allclose(np.rad2deg(kin.JOINT_UPPER[[0, 1, 3, 4, 5]]), [91, 53, 260, 80, 80])
    assert (kin.JOINT_LOWER[2], kin.JOINT_UPPER[2]) == (0.0, 0.24)
    np.testing.assert_allclose(kin.JOINT_LOWER[[0, 1, 3, 4, 5]], -kin.JOINT_UPPER[[0, 1, 3, 4, 5]])
    with pytest.raises(ValueError):
        kin.JOINT_LOWER[0] = 0.0


# --- jaws -----------------------------------------------------------------------------


def test_closed_jaw_tips_coincide_one_jaw_length_along_tool_z() -> None:
    q = np.array([0.3, -0.2, 0.12, 1.1, 0.4, -0.5])
    tips = kin.jaw_tip_positions(q, 0.0)
    pose = kin.forward_kinematics(q)
    expected = pose[:3, 3] + kin.JAW_LENGTH_M * pose[:3, 2]
    np.testing.assert_allclose(tips, [expected, expected], atol=1e-15)


def test_fully_open_jaws_separate_by_chord_symmetrically_about_tool_z() -> None:
    q = np.array([0.3, -0.2, 0.12, 1.1, 0.4, -0.5])
    tips = kin.jaw_tip_positions(q, kin.JAW_FULLY_OPEN_RAD)
    pose = kin.forward_kinematics(q)
    separation = np.linalg.norm(tips[0] - tips[1])
    assert separation == pytest.approx(2 * kin.JAW_LENGTH_M * np.sin(np.deg2rad(37.5)), abs=1e-15)
    midpoint = tips.mean(axis=0)
    along = kin.JAW_LENGTH_M * np.cos(np.deg2rad(37.5))
    np.testing.assert_allclose(midpoint, pose[:3, 3] + along * pose[:3, 2], atol=1e-15)
    # The jaws open in the plane normal to the wrist-yaw axis (frame-6 z).
    yaw_axis = kin.link_frames(q)[-1][:3, 2]
    assert abs((tips[0] - tips[1]) @ yaw_axis) < 1e-15


def test_jaw_angle_outside_range_is_rejected() -> None:
    with pytest.raises(ValueError, match="jaw angle"):
        kin.jaw_tip_positions(ZERO_Q, np.deg2rad(90.0))


def test_touch_point_is_closed_tip_when_tool_points_down() -> None:
    expected = [0.0, 0.0, -0.1735 - kin.JAW_LENGTH_M]
    np.testing.assert_allclose(kin.touch_point(ZERO_Q), expected, atol=1e-15)


def test_touch_point_is_lower_end_of_closed_jaws() -> None:
    rng = np.random.default_rng(7)
    picked_pivot = picked_tip = 0
    for q in _random_q(rng, 500, (0.05, 0.24)):
        pivot = kin.forward_kinematics(q)[:3, 3]
        tip = kin.jaw_tip_positions(q, 0.0)[0]
        point = kin.touch_point(q)
        lower = tip if tip[2] <= pivot[2] else pivot
        np.testing.assert_allclose(point, lower, atol=1e-15)
        picked_tip += tip[2] <= pivot[2]
        picked_pivot += tip[2] > pivot[2]
    assert picked_tip > 0 and picked_pivot > 0


# --- Euler angles and the paper's orientation rule -------------------------------------


def test_euler_matches_intrinsic_zyx_and_round_trips() -> None:
    rng = np.random.default_rng(3)
    for yaw, pitch, roll in rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], size=(200, 3)):
        pose = kin.pose_from_euler([0.01, -0.02, -0.15], yaw, pitch, roll)
        expected = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        np.testing.assert_allclose(pose[:3, :3], expected, atol=1e-15)
        np.testing.assert_allclose(kin.euler_from_pose(pose), [yaw, pitch, roll], atol=1e-12)


def test_euler_roll_near_minus_pi_points_tool_z_down() -> None:
    pose = kin.pose_from_euler([0, 0, 0], 0.0, 0.0, np.deg2rad(-170.0))
    assert pose[2, 2] < -0.98


def test_euler_gimbal_lock_returns_equivalent_angles_without_warning() -> None:
    pose = kin.pose_from_euler([0, 0, 0], 0.4, np.pi / 2, 0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yaw, pitch, roll = kin.euler_from_pose(pose)
    assert pitch == pytest.approx(np.pi / 2)
    assert roll == 0.0
    np.testing.assert_allclose(kin.pose_from_euler([0, 0, 0], yaw, pitch, roll), pose, atol=1e-12)


def test_paper_pitch_roll_of_one_yaw_is_the_array_rules_value_bit_for_bit() -> None:
    """One yaw takes a plain-float path (0.35 us, against 13 to 16 timed beside it): the array path's bits, as Python floats."""
    yaws = np.random.default_rng(0).uniform(-3.2, 3.2, 2000)
    pitches, rolls = kin.paper_pitch_roll(yaws)
    for yaw, pitch, roll in zip(yaws, pitches, rolls):
        for one in (float(yaw), yaw):  # a Python float, an np.float64
            got = kin.paper_pitch_roll(one)
            assert [type(v) for v in got] == [float, float] and got == (pitch, roll)
    assert kin.paper_pitch_roll(1) == tuple(v[0] for v in kin.paper_pitch_roll(np.array([1.0])))
    for bad in (float("nan"), float("inf"), np.float64("-inf")):
        with pytest.raises(ValueError, match="yaw_rad must be finite"):
            kin.paper_pitch_roll(bad)


def test_paper_pitch_roll_endpoints_and_midpoint() -> None:
    deg = np.deg2rad
    assert np.allclose(kin.paper_pitch_roll(deg(-90.0)), deg([0.0, -170.0]))
    assert np.allclose(kin.paper_pitch_roll(deg(90.0)), deg([10.0, -165.0]))
    assert np.allclose(kin.paper_pitch_roll(0.0), deg([5.0, -167.5]))
    pitch, roll = kin.paper_pitch_roll(deg(np.array([-90.0, 0.0, 90.0])))
    np.testing.assert_allclose(np.rad2deg(pitch), [0.0, 5.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(np.rad2deg(roll), [-170.0, -167.5, -165.0], atol=1e-12)


def test_nearest_paper_yaw_scalar_and_vectorised() -> None:
    np.testing.assert_allclose(np.rad2deg(kin.PAPER_YAWS_RAD), [-90, -45, 0, 45, 90])
    assert kin.nearest_paper_yaw(np.deg2rad(30.0)) == pytest.approx(np.deg2rad(45.0))
    result = kin.nearest_paper_yaw(np.deg2rad([-100.0, -50.0, 10.0, 80.0, -170.0]))
    np.testing.assert_allclose(np.rad2deg(result), [-90.0, -45.0, 0.0, 90.0, -90.0])


def test_clamped_inverse_kinematics_equals_exact_ik_when_reachable_and_clamps_otherwise():
    pose = kin.pose_from_euler([0.04, 0.04, -0.154], 0.0, np.radians(5), np.radians(-167))
    q, mask = ik.inverse_kinematics_clamped(pose)
    np.testing.assert_array_equal(q, ik.inverse_kinematics(pose))
    assert not mask.any()
    far = kin.pose_from_euler([0.04, 0.04, -0.154], 0.0, np.radians(5), np.radians(-60))
    with pytest.raises(ik.UnreachablePoseError):
        ik.inverse_kinematics(far)
    q, mask = ik.inverse_kinematics_clamped(far)
    assert mask.any() and kin.within_joint_limits(q, tolerance=0.0)
