"""The float paths of issue 18 (GridTouch's touch evaluations, moves, resets and stereo view in
Python floats) against numpy's.

Unlike tests/test_fast_paths.py these are not bit for bit: numpy's 3x3 / 4x4 products (BLAS)
fuse multiply-adds, the gravity sag's least squares is solved in closed form, and math's
atan2 / hypot / tanh can differ from numpy's in the last bit. Each test bounds the
difference to a few ulps of the values (well under any error a wrong formula would make)
and checks that the paths fall back to numpy exactly where they must.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dvrk_gym.envs.grid_touch import SURFACE_Z_M
from dvrk_gym.envs.tool_pose import tool_pose, tool_rotation
from dvrk_gym.sim.robot import cables, ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import resolve_bias
from dvrk_gym.sim.world import DvrkWorld
from dvrk_gym.sim.world_config import WorldConfig

ULPS_M = 2e-15  # positions of ~0.2 m: about 70 ulps
ULPS_RAD = 2e-14  # angles up to ~5 rad (roll branches): about 20 ulps


def _random_q(rng: np.random.Generator, spread: float = 0.9) -> np.ndarray:
    q = rng.uniform(kin.JOINT_LOWER * spread, kin.JOINT_UPPER * spread)
    q[2] = rng.uniform(0.05, 0.23)
    return q


@pytest.mark.parametrize("preset", ["none", "paper", "severe"])
def test_the_float_chain_and_touch_point_match_numpys(preset):
    dh = cables.CableModel(resolve_bias(preset), bias_seed=5).true_dh
    rng = np.random.default_rng(1)
    lower_points = 0
    for _ in range(300):
        q = _random_q(rng)
        frame = np.array(ik.last_frame_floats(q.tolist(), dh)).reshape(3, 4)
        np.testing.assert_allclose(frame, kin.last_frame(q, dh)[:3], rtol=0, atol=ULPS_M)
        reference = kin.touch_point(q, dh)
        np.testing.assert_allclose(ik.touch_point_floats(q.tolist(), dh), reference, rtol=0, atol=ULPS_M)
        lower_points += bool(reference[2] < kin.last_frame(q, dh)[2, 3])
    assert 0 < lower_points < 300  # both ends of the jaws were the lowest point


def test_the_float_inverse_kinematics_matches_numpys_or_hands_over():
    rng = np.random.default_rng(2)
    solved = handed_over = 0
    for _ in range(600):
        q = _random_q(rng, spread=1.15)  # some poses need joints past their limits
        pose = kin.forward_kinematics(q)
        q_ref = rng.uniform(-4.0, 4.0, 6)
        floats = ik.inverse_kinematics_floats(pose[:3, 3].tolist(), pose[:3, :3], q_ref)
        expected, clamped = ik.inverse_kinematics_clamped(pose, q_ref)
        if floats is None:  # only where the numpy path clamps (or solves on another branch)
            handed_over += 1
            assert clamped.any() or not kin.within_joint_limits(q, 0.0)
            continue
        solved += 1
        assert not clamped.any()
        np.testing.assert_allclose(floats, expected, rtol=0, atol=ULPS_RAD)
        assert kin.within_joint_limits(np.array(floats))
    assert solved > 300 and handed_over > 30


@pytest.mark.parametrize("settle_lag", [0.0, 0.25])
def test_the_float_peek_matches_numpys_and_moves_nothing(settle_lag):
    config = dataclasses.replace(resolve_bias("severe"), wrist_settle_lag=settle_lag)
    model = cables.CableModel(config, bias_seed=4)
    rng = np.random.default_rng(3)
    q0 = _random_q(rng)
    assert model.peek_true_joints_floats(q0.tolist()) == model.peek_true_joints(q0).tolist()  # no history: numpy's
    for _ in range(5):
        model.true_joints(_random_q(rng), rng)
    for _ in range(300):
        q = _random_q(rng)
        state = model.get_state()
        floats = model.peek_true_joints_floats(q.tolist())
        assert model.get_state().tobytes() == state.tobytes()
        np.testing.assert_allclose(floats, model.peek_true_joints(q), rtol=0, atol=ULPS_M)
        model.true_joints(q if rng.random() < 0.5 else _random_q(rng), rng)  # a history of moves, reversals too


def test_the_float_plays_and_their_sums_are_numpys_bit_for_bit():
    radii = cables.play_radii(resolve_bias("severe"))
    rng = np.random.default_rng(4)
    for _ in range(300):
        q = _random_q(rng)
        plays = q + rng.normal(0.0, 3.0, radii.shape) * radii
        updated = cables.play_update(plays, q, radii)
        got = [cables._play_floats(m, p, r) for m, p, r in zip(q.tolist(), zip(*plays.tolist()), radii.T.tolist())]
        assert np.array([column for column, _ in got]).T.tobytes() == updated.tobytes()
        assert np.array([total for _, total in got]).tobytes() == np.add.reduce(q - updated, axis=0).tobytes()


def test_the_float_gravity_sag_matches_the_least_squares():
    config = resolve_bias("severe")
    rng = np.random.default_rng(5)
    for _ in range(300):
        q = _random_q(rng)
        np.testing.assert_allclose(cables._gravity_sag_floats(q.tolist(), config), cables.gravity_sag(q, config), rtol=1e-12, atol=1e-18)


def test_grid_touch_tool_rotation_feeds_the_float_path_the_pose_of_tool_pose():
    pose = tool_pose(np.array([0.01, 0.02, -0.1]), 0.4)
    assert tool_rotation(0.4).tobytes() == pose[:3, :3].tobytes()


def _reference_contact_height(world: DvrkWorld, target: np.ndarray, yaw: float) -> float:
    """GridTouch's contact search as it was: the cable state copied out and back per point."""

    def tip_z(position: np.ndarray) -> float:
        state = world.cable.get_state()
        q_cmd, _ = ik.inverse_kinematics_clamped(tool_pose(position, yaw), q_ref=world.q_cmd)
        tip = kin.touch_point(world.cable.true_joints(q_cmd), world.cable.true_dh)
        world.cable.set_state(state)
        return float(tip[2])

    z = float(target[2])
    if tip_z(target) >= SURFACE_Z_M:
        return z
    for _ in range(8):
        gap = tip_z(np.array([target[0], target[1], z])) - SURFACE_Z_M
        if abs(gap) < 1e-7:
            break
        z -= gap
    return z


def test_grid_touch_contact_search_finds_the_height_of_the_numpy_path(make_env):
    env = make_env("dvrk_gym/GridTouch-v0")
    env.reset(seed=0)
    grid = env.unwrapped
    rng = np.random.default_rng(7)
    heights = []
    for _ in range(40):
        centre = grid.circle_centers[rng.integers(len(grid.circle_centers))]
        target = np.array([centre[0], centre[1], centre[2] + rng.uniform(-0.006, 0.015)])
        yaw = float(rng.uniform(-np.pi / 2, np.pi / 2))
        grid.world.move_to(tool_pose(target + [0.0, 0.0, 0.008], yaw), noise_rng=rng, clamp_to_limits=True)
        z = grid._contact_height(target, yaw)
        assert abs(z - _reference_contact_height(grid.world, target, yaw)) <= 1e-12  # m
        heights.append(z != target[2])
    assert any(heights) and not all(heights)  # both branches: into the paper and above it


@pytest.mark.parametrize("settle_lag", [0.0, 0.25])
def test_the_float_move_of_the_cables_matches_numpys_state_draw_and_joints(settle_lag):
    config = dataclasses.replace(resolve_bias("severe"), wrist_settle_lag=settle_lag)
    floats, reference = (cables.CableModel(config, bias_seed=6) for _ in range(2))
    rng = np.random.default_rng(8)
    q0 = _random_q(rng)
    first = floats.true_joints_floats(q0.tolist())  # no history: numpy's path, exactly
    assert first == reference.true_joints(q0).tolist()
    for i in range(300):
        q = _random_q(rng) if i % 3 else q0 + rng.normal(0.0, 0.01, 6)  # small moves reverse inside the plays
        seed = int(rng.integers(2**32))
        noise = (np.random.default_rng(seed), np.random.default_rng(seed)) if i % 2 else (None, None)
        got = floats.true_joints_floats(q.tolist(), noise[0])
        np.testing.assert_allclose(got, reference.true_joints(q, noise[1]), rtol=0, atol=ULPS_RAD)
        assert floats.get_state().tobytes() == reference.get_state().tobytes()  # the plays are clip choices: exact
        if noise[0] is not None:  # the same draw was taken
            assert noise[0].random() == noise[1].random()


def test_the_float_forward_kinematics_matches_numpys():
    rng = np.random.default_rng(9)
    for _ in range(300):
        q = _random_q(rng)
        np.testing.assert_allclose(ik.forward_kinematics_floats(q.tolist()), kin.forward_kinematics(q), rtol=0, atol=ULPS_M)


def test_the_float_projection_triangulation_and_pixel_noise_match_the_cameras():
    world = DvrkWorld()
    camera, rng = world.camera, np.random.default_rng(10)
    noise = dataclasses.replace(world.pixel_noise, sigma_px_at_1080p=0.7)
    for _ in range(200):
        point = np.array([0.04, 0.042, -0.16]) + rng.uniform(-0.04, 0.04, 3)
        lu, lv, ru = camera.project_point_floats(point.tolist())
        left, right = camera.project(point)
        np.testing.assert_allclose([lu, lv, ru, lv], [*left[0], *right[0]], rtol=0, atol=1e-10)  # px: ulps of ~1000
        seed = int(rng.integers(2**32))
        a, b = np.random.default_rng(seed), np.random.default_rng(seed)
        noisy = (noise.apply_floats(lu, lv, a), noise.apply_floats(ru, lv, a))
        expected = (noise.apply(np.array([lu, lv]), b), noise.apply(np.array([ru, lv]), b))
        assert np.array(noisy).tobytes() == np.array(expected).tobytes()
        assert np.array(camera.triangulate_floats(*noisy)).tobytes() == camera.triangulate(*expected)[0].tobytes()
    with pytest.raises(ValueError, match="non-positive disparity"):
        camera.triangulate_floats((500.0, 400.0), (500.0, 401.0))


@pytest.mark.parametrize("bias", ["none", "paper"])  # paper's wrist settle lag makes the reported pose the motors'
def test_a_float_move_of_the_world_is_numpys_move_to_a_few_ulps(bias):
    floats, reference = DvrkWorld(WorldConfig(bias=bias)), DvrkWorld(WorldConfig(bias=bias))
    rng = np.random.default_rng(11)
    for i in range(60):
        pose = tool_pose(np.array([0.04, 0.042, -0.155]) + rng.uniform(-0.03, 0.03, 3), float(rng.uniform(-1.5, 1.5)))
        command = ik.inverse_kinematics_floats(pose[:3, 3].tolist(), pose[:3, :3], floats.q_cmd)
        assert command is not None
        seed = int(rng.integers(2**32))
        got = floats.move_joints_floats(command, noise_rng=np.random.default_rng(seed))
        expected = reference.move_joints(np.array(command), noise_rng=np.random.default_rng(seed))
        assert got.q_cmd.tobytes() == expected.q_cmd.tobytes() and not got.joints_clamped.any()
        np.testing.assert_allclose(got.q_true, expected.q_true, rtol=0, atol=ULPS_RAD)
        assert abs(got.duration_s - expected.duration_s) <= 1e-12
        assert floats.cable.get_state().tobytes() == reference.cable.get_state().tobytes()
        reported = floats.reported_pose()  # numpy's forward kinematics, bit for bit
        assert reported.tobytes() == kin.forward_kinematics(floats.cable.measured_joints(floats.q_cmd)).tobytes()
        assert reported.tobytes() == reference.reported_pose().tobytes()
        if i % 20 == 19:  # a reset keeping the cables' history, in floats and in numpy
            floats.reset_robot(got.q_cmd, relax=False, floats=True)
            reference.reset_robot(expected.q_cmd, relax=False)
            np.testing.assert_allclose(floats.q_true, reference.q_true, rtol=0, atol=ULPS_RAD)
            assert floats.cable.get_state().tobytes() == reference.cable.get_state().tobytes()


def _on_the_numpy_path(env) -> None:
    """Send a GridTouch env's moves, resets and stereo view back to the numpy path."""
    world = env.unwrapped.world
    reset_robot, camera = world.reset_robot, world.camera
    world.move_joints_floats = lambda q, noise_rng=None: world.move_joints(np.array(q), noise_rng=noise_rng)
    world.reset_robot = lambda q, jaw_angle_rad=0.0, relax=True, floats=False: reset_robot(q, jaw_angle_rad, relax)

    def project(point):
        left, right = camera.project(np.array(point))
        return float(left[0, 0]), float(left[0, 1]), float(right[0, 0])

    camera.project_point_floats = project


@pytest.mark.parametrize("bias", ["none", "paper", "severe"])
def test_grid_touch_through_the_worlds_float_moves_sees_what_it_sees_through_numpys(make_env, bias):
    """The world's float moves, resets and projection give GridTouch the episodes numpy's
    give, bit for bit. Only those three are swapped: the env's inverse kinematics, true tip,
    contact probe, pixel noise and triangulation run on the float paths in both envs, and
    each is compared with numpy's on its own above (and the compiled ones with the Python
    float paths in test_compiled_paths.py)."""
    envs = [make_env("dvrk_gym/GridTouch-v0", bias=bias, pixel_noise_px=0.5) for _ in range(2)]
    _on_the_numpy_path(envs[1])
    records = []
    for env in envs:
        env.action_space.seed(3)
        record = [env.reset(seed=3)]
        for i in range(120):
            observation, reward, _, _, info = env.step(env.action_space.sample())
            record.append((observation, reward, info))
            record.append(env.reset(options={"yaw": "random"} if i == 60 else None))
        records.append(record)
    for got, expected in zip(*records):
        for key in got[0]:
            assert got[0][key].tobytes() == expected[0][key].tobytes()
        if len(got) == 3:  # a step
            assert got[1] == expected[1]
            for key in ("reported_position", "human_correction"):  # the cables' state and the reported pose: exact
                assert got[2][key].tobytes() == expected[2][key].tobytes()
            np.testing.assert_allclose(got[2]["true_tip_position"], expected[2]["true_tip_position"], rtol=0, atol=ULPS_M)
            assert abs(got[2]["pixel_error"] - expected[2]["pixel_error"]) <= 1e-11
