"""The fast paths of issue 18 give the very numbers of the code they replaced, bit for bit.

Each test runs a reference written as the code was before (one link transform at a time,
the cable state copied out and back, ``np.linalg.lstsq``, ``np.remainder``, scipy's angle
for every move...) beside the fast path, and compares the bytes: a refactor that changed a
rounding anywhere would change an episode, which the envs promise not to do.
"""

from __future__ import annotations

import dataclasses
import gc

import numpy as np
import pybullet
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.robot import cables, ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import resolve_bias
from dvrk_gym.sim.robot.motion import CartesianMove, MotionLimits, rotation_angle_bound, trapezoid_timing
from dvrk_gym.sim.world import DvrkWorld, WorldConfig


def _same(a: object, b: object) -> bool:
    return np.asarray(a, dtype=float).tobytes() == np.asarray(b, dtype=float).tobytes()


def _random_q(rng: np.random.Generator) -> np.ndarray:
    q = rng.uniform(kin.JOINT_LOWER * 0.9, kin.JOINT_UPPER * 0.9)
    q[2] = rng.uniform(0.05, 0.23)
    return q


def _reference_frames(q: np.ndarray, dh: tuple[kin.DHRow, ...]) -> np.ndarray:
    """link_frames as it was: one dh_transform per row, multiplied in turn from the identity."""
    frames, current = [], np.eye(4)
    for row, qi in zip(dh, q):
        current = current @ kin.dh_transform(row, qi)
        frames.append(current)
    return np.array(frames)


@pytest.mark.parametrize("preset", ["none", "paper", "severe"])
def test_link_frames_fk_and_tips_equal_the_product_of_each_rows_transform(preset):
    dh = cables.CableModel(resolve_bias(preset), bias_seed=5).true_dh
    rng = np.random.default_rng(0)
    for _ in range(300):
        q = _random_q(rng)
        reference = _reference_frames(q, dh)
        for i, (row, qi) in enumerate(zip(dh, q)):
            assert _same(kin.dh_transforms(q, dh)[i], kin.dh_transform(row, qi))
        assert _same(kin.link_frames(q, dh), reference)
        assert _same(kin.last_frame(q, dh), reference[-1])
        pose = reference[-1].copy()
        pose[:3, :3] = pose[:3, :3] @ kin.TOOL_TIP_ROTATION
        assert _same(kin.forward_kinematics(q, dh), pose)
        tip = reference[-1][:3, 3] + kin.JAW_LENGTH_M * reference[-1][:3, 1]
        expected_touch = tip if tip[2] <= reference[-1][2, 3] else reference[-1][:3, 3]
        assert _same(kin.touch_point(q, dh), expected_touch)


def _reference_wrap(angle: float) -> float:
    return float(-np.remainder(-angle + np.pi, 2 * np.pi) + np.pi)


def _reference_choose_roll(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    branches = q[3] + 2 * np.pi * np.arange(-2, 3)
    in_limits = (branches >= kin.JOINT_LOWER[3]) & (branches <= kin.JOINT_UPPER[3])
    candidates = branches[in_limits] if in_limits.any() else branches
    q = q.copy()
    q[3] = candidates[np.argmin(np.abs(candidates - q_ref[3]))]
    return q


def test_angle_wrap_and_roll_branch_equal_their_numpy_forms():
    rng = np.random.default_rng(1)
    angles = np.concatenate([rng.uniform(-20.0, 20.0, 5000), [0.0, -0.0, np.pi, -np.pi, 3 * np.pi, 1e-300]])
    for angle in angles:
        assert _same(ik._wrap(angle), _reference_wrap(angle))
    for _ in range(3000):
        q, q_ref = _random_q(rng), _random_q(rng)
        q[3] = rng.uniform(-np.pi, np.pi)
        q_ref[3] = rng.choice([q[3] + 2 * np.pi, q[3] - 2 * np.pi, rng.uniform(-4.5, 4.5)])
        assert _same(ik._choose_roll(q, q_ref), _reference_choose_roll(q, q_ref))


def test_least_squares_equals_numpy_lstsq_even_when_rank_deficient():
    rng = np.random.default_rng(2)
    for _ in range(2000):
        a, b = rng.normal(size=(3, 2)), rng.normal(size=3)
        if rng.random() < 0.2:
            a[:, 1] = 2.0 * a[:, 0]  # rank 1
        assert _same(cables._least_squares(a, b), np.linalg.lstsq(a, b, rcond=None)[0])


def test_peek_true_joints_is_a_noiseless_move_undone_and_moves_nothing():
    model = cables.CableModel(resolve_bias("paper"), bias_seed=3)
    rng = np.random.default_rng(3)
    for history in (False, True):  # NaN state (no history yet), then a history of moves
        if history:
            for _ in range(5):
                model.true_joints(_random_q(rng), rng)
        for _ in range(200):
            q = _random_q(rng)
            state = model.get_state()
            peeked = model.peek_true_joints(q)
            assert _same(model.get_state(), state)
            assert _same(peeked, model.true_joints(q))
            model.set_state(state)


def _reference_plan(start: np.ndarray, end: np.ndarray, limits: MotionLimits) -> tuple[float, float]:
    distance = float(np.linalg.norm(end[:3, 3] - start[:3, 3]))
    angle = float(Rotation.from_matrix(start[:3, :3].T @ end[:3, :3]).magnitude())
    linear = trapezoid_timing(distance, limits.max_speed_m_s, limits.max_accel_m_s2)
    angular = trapezoid_timing(angle, limits.max_angular_speed_rad_s, limits.max_angular_accel_rad_s2)
    return max(linear, angular)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    st.floats(0.0, np.pi),
    st.sampled_from([1.0, 1e-3, 1e-6, 1e-9, 1e-12]),
)
def test_the_angle_bound_never_falls_below_scipys_angle(axis, angle, scale):
    axis_array = np.array(axis) + [1e-3, 0.0, 0.0]
    rotation = Rotation.from_rotvec(axis_array / np.linalg.norm(axis_array) * angle * scale).as_matrix()
    assert rotation_angle_bound(rotation) >= float(Rotation.from_matrix(rotation).magnitude())


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    st.sampled_from([1e-6, 1e-3, 0.5, 2.9, 3.0, 3.1, np.pi - 1e-6, np.pi]),
    st.integers(0, 2**32 - 1),
)
def test_the_angle_bound_holds_for_matrices_off_orthonormal_as_far_as_ik_accepts(axis, angle, seed):
    axis_array = np.array(axis) + [1e-3, 0.0, 0.0]
    rotation = Rotation.from_rotvec(axis_array / np.linalg.norm(axis_array) * angle).as_matrix()
    rotation += np.random.default_rng(seed).uniform(-3e-7, 3e-7, (3, 3))  # off orthonormal by under 1e-6
    assert rotation_angle_bound(rotation) >= float(Rotation.from_matrix(rotation).magnitude())


def test_a_planned_move_lasts_as_long_as_with_scipys_angle_for_every_move():
    rng = np.random.default_rng(4)
    limits = [MotionLimits(), MotionLimits(max_speed_m_s=0.065, max_accel_m_s2=0.65), MotionLimits(max_speed_m_s=0.03, max_accel_m_s2=0.3)]
    for _ in range(1500):
        start = kin.forward_kinematics(_random_q(rng))
        end = start.copy() if rng.random() < 0.3 else kin.forward_kinematics(_random_q(rng))
        end[:3, 3] += rng.normal(0.0, 10.0 ** rng.uniform(-6, -1), 3)
        if rng.random() < 0.5:  # same orientation: the bound decides alone
            end[:3, :3] = start[:3, :3]
        for limit in limits:
            move = CartesianMove.plan(start, end, limit)
            assert _same([move.duration_s, move.ramp_s], _reference_plan(start, end, limit))


def test_tool_pose_equals_the_paper_rule_pose_from_its_cache_too():
    rng = np.random.default_rng(5)
    for yaw in [*rng.uniform(-np.pi / 2, np.pi / 2, 300), 0.0, -0.0]:  # -0.0 after 0.0 is cached: its own entry
        position = rng.uniform(-0.1, 0.1, 3)
        pitch, roll = kin.paper_pitch_roll(yaw)
        expected = kin.pose_from_euler(position, yaw, float(pitch), float(roll))
        assert _same(tool_pose(position, yaw), expected)
        assert _same(tool_pose(position, yaw), expected)  # from the cache now
    with pytest.raises(ValueError, match="position"):
        tool_pose(np.array([0.0, np.nan, 0.0]), 0.1)


@pytest.fixture
def world():
    made = DvrkWorld(WorldConfig(camera_resolution=(320, 180)))
    yield made
    made.close()


@pytest.fixture
def commanded_world():
    """A world whose encoders read the command (no settle lag): its reported pose is FK(q_cmd)."""
    made = DvrkWorld(WorldConfig(bias=dataclasses.replace(resolve_bias("paper"), wrist_settle_lag=0.0), camera_resolution=(320, 180)))
    yield made
    made.close()


def test_the_reported_pose_follows_every_change_of_the_command(commanded_world):
    world = commanded_world
    rng = np.random.default_rng(6)
    for _ in range(20):
        q = _random_q(rng)
        world.q_cmd = q
        assert _same(world.reported_pose(), kin.forward_kinematics(q))
        world.q_cmd[0] += 0.01  # changed in place
        assert _same(world.reported_pose(), kin.forward_kinematics(world.q_cmd))
        world.reported_pose()[0, 3] = 99.0  # a caller's copy: the next reading is untouched
        assert _same(world.reported_pose(), kin.forward_kinematics(world.q_cmd))


def test_a_physics_client_forgets_its_bound_functions_when_it_disconnects():
    physics = Physics()
    client = physics.client
    client.getNumBodies()
    assert "getNumBodies" in vars(client)  # bound once, kept
    physics.close()
    gc.collect()
    assert "getNumBodies" not in vars(client)
    with pytest.raises(pybullet.error):
        client.getNumBodies()  # no stale server id: the call fails as BulletClient's does
