"""The compiled float paths (dvrk_gym.sim.compiled) are the Python float paths', bit for bit.

GridTouch-v0's contact search and simulated person call it about seven times a step; its
results reach the Phase II corrections and so the residual forests, where a last bit that
moves moves a split. So these tests ask for equal bytes, not closeness.
"""

from __future__ import annotations

import ast
import dataclasses
import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from dvrk_gym.envs.tool_pose import tool_rotation
from dvrk_gym.sim.compiled import float_paths, kernels
from dvrk_gym.sim.robot import cables, ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import resolve_bias


def _python_tip(model: cables.CableModel, position: np.ndarray, rotation: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    command = ik.inverse_kinematics_clamped_floats(position.tolist(), rotation, q_ref)
    return ik.touch_point_floats(model.peek_true_joints_floats(command), model.true_dh)


@pytest.mark.parametrize(("preset", "settle_lag"), [("none", None), ("paper", None), ("paper", 0.0), ("severe", None)])
def test_the_compiled_true_tip_is_the_python_float_paths_bit_for_bit(preset, settle_lag):
    config = resolve_bias(preset)
    if settle_lag is not None:
        config = dataclasses.replace(config, wrist_settle_lag=settle_lag)
    rng = np.random.default_rng(7)
    model = cables.CableModel(config, bias_seed=3)
    model.reset(np.array([0.3, -0.2, 0.15, 0.1, 0.2, -0.1]))
    constants = float_paths.CableConstants(model)
    compiled_ik = fallbacks = 0
    for i in range(1500):
        q = rng.uniform(kin.JOINT_LOWER * 0.8, kin.JOINT_UPPER * 0.8)
        q[2] = rng.uniform(0.06, 0.22)
        if i % 3 == 0:  # move, so that the plays and motors take many states
            model.true_joints(q, rng)
        position = kin.touch_point(q) + rng.normal(0.0, 0.02, 3)  # some of these need clamped joints
        rotation = tool_rotation(float(rng.uniform(-np.pi / 2, np.pi / 2)))
        q_ref = rng.uniform(-4.0, 4.0, 6)
        state = model.get_state()
        r6 = (rotation @ kin.TOOL_TIP_ROTATION.T).ravel()
        handed_over = []

        def fallback(position=position, rotation=rotation, q_ref=q_ref, handed_over=handed_over):
            handed_over.append(True)
            return ik.inverse_kinematics_clamped_floats(position.tolist(), rotation, q_ref)

        got = float_paths.true_tip(position, r6, float(q_ref[3]), state, constants=constants, fallback_command=fallback)
        assert got.tobytes() == _python_tip(model, position, rotation, q_ref).tobytes()
        assert model.get_state().tobytes() == state.tobytes()  # a peek moves nothing
        python_solved = ik.inverse_kinematics_floats(position.tolist(), rotation, q_ref) is not None
        assert bool(handed_over) == (not python_solved)  # hands over exactly where the Python path does
        compiled_ik += python_solved
        fallbacks += not python_solved
    assert compiled_ik > 1000 and fallbacks > 20  # both branches were taken


def test_the_compiled_hypot_is_pythons():
    rng = np.random.default_rng(0)
    pairs = [(0.0, 0.0), (0.0, -2.5), (3.0, 4.0), (-1e-3, 1e-3), (1.0, 1e-300), (5e-324, 0.0)]
    for scale in (1.0, 1e-2, 1e-4):
        pairs += list(zip(rng.normal(0.0, scale, 20000).tolist(), (rng.normal(0.0, scale, 20000) * rng.uniform(0, 3, 20000)).tolist()))
    mismatches = [(a, b) for a, b in pairs if kernels._hypot(a, b) != math.hypot(a, b)]
    assert mismatches == []


def test_the_compiled_squares_are_the_c_librarys_pow_not_a_product():
    """LLVM turns pow(x, 2.0) with a constant 2 into x * x, which is not Python's x ** 2: the
    inverse kinematics' norms, sqrt(x**2 + y**2 + z**2), would differ in the last bit."""
    rng = np.random.default_rng(1)
    values = rng.normal(0.0, 0.1, 20000).tolist()
    assert [v for v in values if kernels._square(v, 2.0) != v**2] == []
    assert float_paths.ARM[kernels.TWO] == 2.0
    out, rotation = np.empty(6), tool_rotation(0.3)
    r6 = (rotation @ kin.TOOL_TIP_ROTATION.T).ravel()
    solved = 0
    for _ in range(20000):
        position = np.array([rng.uniform(-0.02, 0.1), rng.uniform(-0.02, 0.1), rng.uniform(-0.19, -0.1)])
        expected = ik.inverse_kinematics_floats(position.tolist(), rotation, np.zeros(6))
        if kernels.inverse_kinematics(position, r6, 0.0, float_paths.ARM, float_paths._OUTER_LINKS, out):
            assert expected is not None and out.tobytes() == np.array(expected).tobytes()
            solved += 1
        else:
            assert expected is None
    assert solved > 15000


def test_grid_touch_probe_is_the_python_float_paths_and_falls_back_without_history(make_env):
    env = make_env("dvrk_gym/GridTouch-v0", bias="severe")
    env.reset(seed=4)
    env.action_space.seed(4)
    grid = env.unwrapped
    rng = np.random.default_rng(4)
    for _ in range(20):
        env.step(env.action_space.sample())
        env.reset()
        yaw = float(rng.uniform(-1.5, 1.5))
        probe = grid._tip_probe(yaw)
        for _ in range(5):
            position = np.array([rng.uniform(0.0, 0.08), rng.uniform(0.0, 0.085), rng.uniform(-0.18, -0.12)])
            assert probe(position).tobytes() == grid._true_tip_floats(position, tool_rotation(yaw)).tobytes()
    for history in (True, False):
        if not history:  # no history: the Python float path, which takes numpy's
            grid.world.cable.set_state(np.full_like(grid.world.cable.get_state(), np.nan))
        position = np.array([0.04, 0.04, -0.15])
        np.testing.assert_array_equal(grid._tip_probe(0.0)(position), grid._true_tip_floats(position, tool_rotation(0.0)))
        for value in (np.nan, np.inf, -np.inf):  # compiled: the inverse kinematics hands over to numpy's, which says so
            with pytest.raises(ValueError, match="finite"):
                grid._tip_probe(0.0)(np.array([value, 0.0, -0.15]))


def test_the_compiled_inverse_kinematics_for_moves_is_the_python_float_paths():
    rng = np.random.default_rng(9)
    solved = clamped = 0
    for _ in range(600):
        q = rng.uniform(kin.JOINT_LOWER * 1.1, kin.JOINT_UPPER * 1.1)  # some poses need joints past their limits
        q[2] = rng.uniform(0.05, 0.23)
        pose = kin.forward_kinematics(q)  # pose[:3, 3] is a strided view: the wrapper copies it
        q_ref = rng.uniform(-4.0, 4.0, 6)
        expected = ik.inverse_kinematics_floats(pose[:3, 3].tolist(), pose[:3, :3], q_ref)
        got = float_paths.inverse_kinematics(pose[:3, 3], pose[:3, :3], q_ref)
        assert (got is None) == (expected is None)
        if got is not None:
            assert np.array(got).tobytes() == np.array(expected).tobytes()
        expected_clamped = ik.inverse_kinematics_clamped_floats(pose[:3, 3].tolist(), pose[:3, :3], q_ref)
        assert (
            np.array(float_paths.inverse_kinematics_clamped(pose[:3, 3], pose[:3, :3], q_ref)).tobytes()
            == np.array(expected_clamped).tobytes()
        )
        solved += got is not None
        clamped += got is None
    assert solved > 200 and clamped > 50


@pytest.mark.parametrize(("preset", "settle_lag"), [("none", None), ("paper", None), ("paper", 0.0), ("severe", None)])
def test_the_compiled_cable_move_is_the_python_float_paths_state_draw_and_joints(preset, settle_lag):
    config = resolve_bias(preset)
    if settle_lag is not None:
        config = dataclasses.replace(config, wrist_settle_lag=settle_lag)
    compiled, python = (cables.CableModel(config, bias_seed=2) for _ in range(2))
    constants = float_paths.CableConstants(compiled)
    rngs = [np.random.default_rng(5), np.random.default_rng(5)]
    rng = np.random.default_rng(6)
    for i in range(400):
        q = rng.uniform(kin.JOINT_LOWER * 0.8, kin.JOINT_UPPER * 0.8).tolist()
        noisy = i % 2 == 0
        got = float_paths.true_joints(compiled, constants, q, rngs[0] if noisy else None)  # the first: no history, the Python path
        expected = python.true_joints_floats(q, rngs[1] if noisy else None)
        assert np.array(got).tobytes() == np.array(expected).tobytes()
        assert compiled.get_state().tobytes() == python.get_state().tobytes()
    assert rngs[0].random() == rngs[1].random()  # the same draws


def test_the_compiled_forward_kinematics_is_the_python_float_paths():
    rng = np.random.default_rng(8)
    for _ in range(500):
        q = rng.uniform(kin.JOINT_LOWER, kin.JOINT_UPPER).tolist()
        assert float_paths.forward_kinematics(q).tobytes() == ik.forward_kinematics_floats(q).tobytes()


def test_the_compiled_touch_point_is_the_python_float_paths():
    rng = np.random.default_rng(10)
    model = cables.CableModel(resolve_bias("severe"), bias_seed=4)
    constants = float_paths.CableConstants(model)
    for _ in range(500):
        q = rng.uniform(kin.JOINT_LOWER, kin.JOINT_UPPER)
        assert float_paths.touch_point(q, constants).tobytes() == ik.touch_point_floats(q.tolist(), model.true_dh).tobytes()


def test_the_kernels_read_no_module_but_math_numba_and_numpy():
    """numba's cache renews a kernel when kernels.py changes, not when a module it read a constant from does."""
    tree = ast.parse(Path(kernels.__file__).read_text())
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported == {"__future__", "math", "numba", "numpy"}


def test_the_compiled_wrap_singular_poses_and_roll_choice_are_the_python_float_paths():
    for angle in (0.0, -0.0, math.pi, -math.pi, 2 * math.pi, -2 * math.pi, 3 * math.pi, 1e-300, math.nextafter(math.pi, 4.0)):
        assert math.copysign(1.0, kernels._wrap(angle)) == math.copysign(1.0, ik._wrap(angle)) and kernels._wrap(angle) == ik._wrap(angle)
    out, eye = np.empty(6), np.eye(3)
    r6 = (eye @ kin.TOOL_TIP_ROTATION.T).ravel()
    n = r6[[2, 5, 8]]
    for position in (np.zeros(3), 0.1 * n, -0.05 * n + 1e-9):  # on the wrist-yaw axis through the RCM: singular
        assert ik.inverse_kinematics_floats(position.tolist(), eye, np.zeros(6)) is None
        assert not kernels.inverse_kinematics(position, r6, 0.0, float_paths.ARM, float_paths._OUTER_LINKS, out)
    position = np.array([0.03, 0.04, -0.15])
    rotation = tool_rotation(0.2)
    for reference in (np.nan, np.inf, 0.0, 2 * math.pi, -2 * math.pi, 1e9):  # ties and no nearest: min()'s first candidate
        q_ref = np.full(6, reference)
        expected = ik.inverse_kinematics_floats(position.tolist(), rotation, q_ref)
        got = float_paths.inverse_kinematics(position, rotation, q_ref)
        assert (got is None) == (expected is None)
        if got is not None:
            assert np.array(got).tobytes() == np.array(expected).tobytes()


def test_grid_touch_on_the_compiled_paths_is_grid_touch_on_the_python_float_paths(make_env, monkeypatch):
    """Every observation, reward and info field of seeded steps and resets, byte for byte."""

    def run(python_floats: bool) -> bytes:
        env = make_env("dvrk_gym/GridTouch-v0", bias="severe", pixel_noise_px=0.5)
        if python_floats:
            _on_the_python_float_paths(monkeypatch, env.unwrapped.world.cable)
        env.action_space.seed(7)
        record = [env.reset(seed=7, options={"yaw": "random"})]
        for i in range(60):
            record.append(env.step(env.action_space.sample()))
            record.append(env.reset(options={"relax": True} if i == 30 else None))
        return pickle.dumps(record)

    assert run(python_floats=False) == run(python_floats=True)


def _on_the_python_float_paths(monkeypatch, cable: cables.CableModel) -> None:
    """Send float_paths' functions back to the Python float paths they compile, for ``cable``."""

    def true_tip(position, r6, roll, state, *, constants, fallback_command):
        q_ref = np.zeros(6)
        q_ref[3] = roll
        rotation = r6.reshape(3, 3) @ kin.TOOL_TIP_ROTATION  # r6 = rotation @ T.T, T a signed permutation: exact
        command = ik.inverse_kinematics_floats(np.asarray(position).tolist(), rotation, q_ref) or list(fallback_command())
        return ik.touch_point_floats(cable.peek_true_joints_floats(command), cable.true_dh)

    monkeypatch.setattr(float_paths, "true_tip", true_tip)
    monkeypatch.setattr(float_paths, "inverse_kinematics", lambda p, r, q: ik.inverse_kinematics_floats(np.asarray(p).tolist(), r, q))
    monkeypatch.setattr(
        float_paths, "inverse_kinematics_clamped", lambda p, r, q: ik.inverse_kinematics_clamped_floats(np.asarray(p).tolist(), r, q)
    )
    monkeypatch.setattr(float_paths, "forward_kinematics", ik.forward_kinematics_floats)
    monkeypatch.setattr(float_paths, "touch_point", lambda q, c: ik.touch_point_floats(np.asarray(q).tolist(), cable.true_dh))
    monkeypatch.setattr(float_paths, "true_joints", lambda model, c, q, rng: model.true_joints_floats(list(q), rng))
