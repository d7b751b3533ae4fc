"""The pick agent (Debridement-v0), the transfer of GridTouch agents to picks, and the light CLI."""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import dvrk_gym  # noqa: F401
from dvrk_gym.baselines import AGENTS, TrainConfig, load_agent, pick_policy, save_agent, train
from dvrk_gym.baselines.agents import build_model
from dvrk_gym.baselines.budgets import AGENT_DESCRIPTIONS, AGENT_ENVS, DEBRIDEMENT_ID
from dvrk_gym.baselines.checkpoints import LoadedAgent
from dvrk_gym.baselines.comparison import calibration_debridement_rows, debridement_row, format_debridement_comparison
from dvrk_gym.baselines.curves import load_curve, plot_curves, save_curve
from dvrk_gym.baselines.picking import (
    MAX_PENALTY_MM,
    OFFSET_SCALE_MM,
    pick_action,
    pick_observation,
    pick_yaw,
    shaped_pick_reward,
    unit_to_pick_box,
    wrap_debridement,
)
from dvrk_gym.baselines.training import make_agent_env, make_training_vec_env
from dvrk_gym.baselines.transfer import GridTouchPickPolicy, PickAgentPolicy
from dvrk_gym.baselines.wrappers import scale_goal
from dvrk_gym.cli.baselines import add_commands
from dvrk_gym.envs.debridement import PICK_HIGH, PICK_LOW, PickTiming, fragment_target
from dvrk_gym.evaluation.trials import Trial, run_trials, totals
from dvrk_gym.sim.robot.kinematics import PAPER_YAWS_RAD, nearest_paper_yaw
from dvrk_gym.sim.robot.motion import MotionLimits
from dvrk_gym.utils.source_fingerprint import SourceFingerprint, source_fingerprint

TINY = (320, 180)
FAST = {"learning_starts": 20, "batch_size": 32, "gradient_steps": 1, "policy_kwargs": {"net_arch": [16, 16]}}
FAST_PICKS = PickTiming(
    travel=MotionLimits(max_speed_m_s=0.3, max_accel_m_s2=3.0),
    descend=MotionLimits(max_speed_m_s=0.15, max_accel_m_s2=1.5),
    carry=MotionLimits(max_speed_m_s=0.15, max_accel_m_s2=1.5),
    grip_dwell_s=0.4,
    drop_fall_s=0.2,
    drop_dwell_s=0.2,
)
"""Picks in half the wall time (faster moves, shorter dwells), for training a few hundred of them in a test."""
PICK_STEPS = 200


@pytest.fixture(scope="module")
def debridement_env():
    env = gym.make(DEBRIDEMENT_ID, camera_resolution=TINY)
    yield env
    env.close()


def _cli():
    parser = argparse.ArgumentParser(prog="dvrk-gym")
    add_commands(parser.add_subparsers(dest="command", required=True))
    return parser


def test_names_and_agents_list_the_same_agents_with_their_envs():
    assert set(AGENTS) == set(AGENT_DESCRIPTIONS) == set(AGENT_ENVS)
    assert AGENTS["sac_pick"].env_id == DEBRIDEMENT_ID
    assert {name: spec.env_id for name, spec in AGENTS.items()} == AGENT_ENVS


def test_unit_actions_map_onto_the_pick_box_and_carry_the_yaw():
    np.testing.assert_allclose(unit_to_pick_box(-np.ones(3)), PICK_LOW[:3])
    np.testing.assert_allclose(unit_to_pick_box(np.ones(3)), PICK_HIGH[:3])
    np.testing.assert_allclose(unit_to_pick_box(np.zeros(3)), (PICK_LOW[:3] + PICK_HIGH[:3]) / 2)
    np.testing.assert_allclose(unit_to_pick_box([3.0, -3.0, 0.0])[:2], [PICK_HIGH[0], PICK_LOW[1]])  # clipped
    action = pick_action(np.zeros(3), 0.25)
    assert action.dtype == np.float32 and action.shape == (4,) and action[3] == pytest.approx(0.25)


def test_fragment_target_refuses_a_seen_fragment_without_a_finite_position() -> None:
    observation = {
        "fragment_seen": np.array([0, 1, 0], np.float32),
        "fragment_positions": np.array([[np.nan] * 3, [0.01, -0.02, 0.19], [0.0] * 3], np.float32),
        "fragment_angles": np.array([np.nan, 0.3, 0.0], np.float32),
    }
    position, _ = fragment_target(observation)  # the first row is not seen: its NaN does not matter
    np.testing.assert_allclose(position, [0.01, -0.02, 0.19], rtol=1e-6)
    for key, row in (("fragment_positions", [0.01, np.nan, 0.19]), ("fragment_angles", np.inf)):
        broken = {name: value.copy() for name, value in observation.items()}
        broken[key][1] = row
        with pytest.raises(ValueError, match="fragment 1 is seen"):
            fragment_target(broken)


def test_pick_observation_is_the_calibrated_policys_target_scaled_with_a_paper_yaw(debridement_env):
    observation, _ = debridement_env.reset(seed=4)
    assert observation["fragment_seen"].any()
    position, angle = fragment_target(observation)
    seen = pick_observation(observation)
    np.testing.assert_allclose(seen[:3], scale_goal(position), atol=1e-6)
    yaw = seen[3] * math.pi / 2
    assert yaw == pytest.approx(float(nearest_paper_yaw(angle)), abs=1e-6)
    assert np.min(np.abs(PAPER_YAWS_RAD - yaw)) < 1e-6


def test_shaped_reward_charges_grip_offset_and_height_in_millimetres():
    assert shaped_pick_reward(
        1.0, {"true_grip_offset_m": np.array([0.0003, 0.0004]), "true_tip_above_fragment_m": -0.001}
    ) == pytest.approx(1 - 0.5 / OFFSET_SCALE_MM)
    assert shaped_pick_reward(0.0, {"true_grip_offset_m": np.array([0.003, 0.004]), "true_tip_above_fragment_m": 0.002}) == pytest.approx(
        -(5 + 2) / OFFSET_SCALE_MM
    )
    assert shaped_pick_reward(0.0, {"true_grip_offset_m": np.array([0.5, 0.0]), "true_tip_above_fragment_m": 0.0}) == pytest.approx(
        -MAX_PENALTY_MM / OFFSET_SCALE_MM
    )
    assert shaped_pick_reward(0.0, {"true_grip_offset_m": None}) == pytest.approx(-MAX_PENALTY_MM / OFFSET_SCALE_MM)


def test_wrapped_pick_sends_the_mapped_command_and_returns_the_shaped_reward(debridement_env):
    env = wrap_debridement(debridement_env)
    observation, _ = env.reset(seed=4)
    raw = debridement_env.unwrapped._last_observation
    np.testing.assert_array_equal(observation["observation"], pick_observation(raw))
    assert env.observation_space.contains(observation)
    unit = np.array([0.2, -0.1, -0.3], dtype=np.float32)
    sent, raw_rewards, raw_step = [], [], debridement_env.step

    def spy(action):
        sent.append(np.array(action, copy=True))
        result = raw_step(action)
        raw_rewards.append(result[1])
        return result

    debridement_env.step = spy
    observation, reward, terminated, _, info = env.step(unit)
    assert len(sent) == 1 and sent[0].tobytes() == pick_action(unit, pick_yaw(raw)).tobytes()  # the box's point, the image rule's yaw
    assert not np.allclose(sent[0][:3], unit)  # not the unit action itself
    assert info["delivered"] == raw_rewards[0]
    assert reward == pytest.approx(shaped_pick_reward(info["delivered"], info))
    assert info["picks"] == 1 and not terminated
    assert info["true_tip_at_grip"] is not None
    np.testing.assert_array_equal(observation["observation"], pick_observation(debridement_env.unwrapped._last_observation))


def test_wrapper_refuses_delta_mode():
    env = gym.make(DEBRIDEMENT_ID, camera_resolution=TINY, action_mode="delta")
    try:
        with pytest.raises(ValueError, match="primitive"):
            wrap_debridement(env)
    finally:
        env.close()


def test_models_log_nowhere():
    config = TrainConfig(agent="sac", steps=1, camera_resolution=TINY)
    env = make_training_vec_env(config)
    try:
        model = build_model(config.spec, env, seed=0)
    finally:
        env.close()
    assert model.logger.get_dir() is None and model.logger.output_formats == []


@pytest.mark.slow
def test_pick_agent_trains_loads_acts_on_raw_observations_and_is_evaluated_by_the_cli(tmp_path, capsys):
    config = TrainConfig(
        agent="sac_pick",
        steps=PICK_STEPS,
        camera_resolution=TINY,
        eval_points=1,
        curve_trials=1,
        overrides=FAST,
        env_overrides={"timing": FAST_PICKS},
    )
    result = train(config, progress=False)
    assert result.env_steps == PICK_STEPS and result.steps_per_second > 0
    assert [p.env_steps for p in result.curve] == [0, PICK_STEPS]
    for point in result.curve:
        assert 0.0 <= point.success_rate <= 1.0 and np.isfinite(point.mm_error) and point.time_per_fragment_s > 0
        assert math.isnan(point.pixel_error)
    saved = save_curve(result.curve, tmp_path / "curve.json", {})
    assert json.loads(saved.read_text())["points"][0]["pixel_error"] is None
    assert [p.success_rate for p in load_curve(saved)] == [p.success_rate for p in result.curve]
    assert plot_curves({"sac_pick": result.curve}, tmp_path / "curve.png", metric="success_rate").stat().st_size > 0

    path = save_agent(result, tmp_path / "model.zip")
    agent = load_agent(path)
    policy = pick_policy(agent)
    assert isinstance(policy, PickAgentPolicy)
    wrapped = make_agent_env(config, training=False)
    try:
        seen, _ = wrapped.reset(seed=7)
        raw = wrapped.unwrapped._last_observation
        expected = pick_action(result.model.predict(seen, deterministic=True)[0], seen["observation"][3] * math.pi / 2)
    finally:
        wrapped.close()
    np.testing.assert_allclose(policy(raw), expected, atol=1e-6)

    args = _cli().parse_args(
        ["baseline", "evaluate", "--model", str(path), "--trials", "1", "--out", str(tmp_path / "eval"), "--no-progress"]
    )
    assert args.func(args) == 0
    assert "success" in capsys.readouterr().out
    rows = json.loads((tmp_path / "eval" / "debridement.json").read_text())["rows"]
    assert [r["method"] for r in rows] == [agent.label]
    reloaded = make_agent_env(agent.config, training=False)  # the settings round-trip through model.json
    try:
        assert reloaded.unwrapped.config.timing == FAST_PICKS
    finally:
        reloaded.close()
    assert rows[0]["picks"] == 8 and rows[0]["robot_moves"] == PICK_STEPS
    assert rows[0]["success"] + rows[0]["missed"] + rows[0]["slipped"] + rows[0]["pierced"] == 8
    assert np.isfinite(rows[0]["time_per_fragment_s"]) and rows[0]["time_per_fragment_s"] > 0
    assert not (tmp_path / "eval" / "baseline_table.json").exists()  # no GridTouch agent: no touch grid


@pytest.mark.slow
def test_grid_touch_agent_transfers_to_picks(tmp_path, debridement_env):
    config = TrainConfig(agent="sac", steps=30, camera_resolution=TINY, eval_points=1, overrides=FAST)
    result = train(config, progress=False)
    agent = LoadedAgent(result.model, config, result.env_steps, tmp_path / "model.zip")
    policy = pick_policy(agent)
    assert isinstance(policy, GridTouchPickPolicy)

    grid = make_agent_env(config, training=False)  # the agent's training view, to compare with
    try:
        home, _ = grid.reset(seed=0, options={"yaw": float(PAPER_YAWS_RAD[3])})
        rescale = grid.env  # GoalScaling(RescaleAction(...)): the action map of training
        observation, _ = debridement_env.reset(seed=4)
        shown = policy.agent_observation(observation)
        position, angle = fragment_target(observation)
        np.testing.assert_allclose(shown["desired_goal"], scale_goal(position), atol=1e-6)
        np.testing.assert_allclose(shown["observation"][:-1], home["observation"][:-1], atol=1e-6)
        np.testing.assert_allclose(shown["achieved_goal"], home["achieved_goal"], atol=1e-4)
        assert shown["observation"][-1] == pytest.approx(float(nearest_paper_yaw(angle)), abs=1e-6)
        unit = result.model.predict(shown, deterministic=True)[0]
        action = policy(observation)
        np.testing.assert_allclose(action[:3], rescale.action(unit), atol=1e-6)
        assert action[3] == pytest.approx(shown["observation"][-1])
    finally:
        grid.close()

    trials = run_trials(debridement_env, policy, 1, seed=2, progress=False)
    total = totals(trials)
    assert total["picks"] == 8 and total["success"] + total["A"] + total["B"] + total["C"] == 8
    assert np.isfinite(total["time_per_fragment_s"])


def test_pick_policy_refuses_agents_of_other_envs():
    other = SimpleNamespace(config=SimpleNamespace(spec=SimpleNamespace(env_id="dvrk_gym/CalibrationExploration-v0")), label="x")
    with pytest.raises(ValueError, match="GridTouch-v0 and dvrk_gym/Debridement-v0"):
        pick_policy(other)
    with pytest.raises(ValueError, match="needs an agent of dvrk_gym/GridTouch-v0"):
        GridTouchPickPolicy(other)
    with pytest.raises(ValueError, match="needs an agent of dvrk_gym/Debridement-v0"):
        PickAgentPolicy(other)


def test_debridement_rows_count_outcomes_and_format():
    trials = [Trial(["-", "-", "A", "-", "B", "-", "-", "-"], 7.0, {}), Trial(["-"] * 8, 8.0, {})]
    row = debridement_row("sac_pick", 5476, trials, "x")
    assert (row.picks, row.success, row.missed, row.slipped, row.pierced) == (16, 14, 1, 1, 0)
    assert row.success_rate == pytest.approx(14 / 16) and row.time_per_fragment_s == pytest.approx(7.5)
    text = format_debridement_comparison([row])
    assert "5,476" in text and "14/16 88%" in text and "7.50" in text


@pytest.mark.parametrize(
    "argv, message",
    [
        (["baseline", "train", "--algo", "sac_pick", "--reward", "dense"], "shaped pick reward"),
        (["baseline", "train", "--algo", "sac", "--fragment", "raisin"], "pick agents"),
        (["baseline", "evaluate", "--model", "m.zip", "--trials", "0"], "--trials"),
    ],
)
def test_cli_refuses_options_that_do_not_fit(argv, message, tmp_path):
    args = _cli().parse_args([*argv, "--out", str(tmp_path / "out")])
    with pytest.raises(ValueError, match=message):
        args.func(args)


def test_bad_names_are_refused_with_the_valid_ones(tmp_path):
    with pytest.raises(ValueError, match="sac_pick"):
        TrainConfig(agent="ppo_pick")
    with pytest.raises(ValueError, match="curve_trials"):
        TrainConfig(agent="sac_pick", curve_trials=0)
    with pytest.raises(ValueError, match="success_rate"):
        plot_curves({}, tmp_path / "x.png", metric="pixels")
    with pytest.raises(ValueError, match="dnn\\+rf"):
        calibration_debridement_rows(tmp_path, calibrators=["svm"])
    with pytest.raises(FileNotFoundError, match="rbt.zip"):
        calibration_debridement_rows(tmp_path, calibrators=["rbt"])


def test_baseline_help_imports_neither_torch_nor_pybullet():
    code = (
        "import sys\n"
        "from dvrk_gym.cli.main import main\n"
        "sys.argv = ['dvrk-gym', 'baseline', 'train', '--help']\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "heavy = sorted(m for m in ('torch', 'pybullet', 'stable_baselines3') if m in sys.modules)\n"
        "print('HEAVY', heavy)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=Path(__file__).parent).stdout
    assert "sac_pick" in out and "HEAVY []" in out


def test_an_agent_picks_on_the_paper_it_learnt_on(monkeypatch):
    """A GridTouch agent that learnt on the rigid paper (an override) picks on it, and the
    comparison says the calibrators' picks met the compliant one; by default both are compliant."""
    from dvrk_gym.baselines import comparison
    from dvrk_gym.calibration.pipeline import PipelineConfig

    rigid = TrainConfig(agent="sac_her", env_overrides={"contact": "rigid"})
    assert comparison.agent_contact(rigid) == "rigid"
    assert comparison.agent_contact(TrainConfig(agent="sac_her")) == comparison.agent_contact(TrainConfig(agent="sac_pick")) == "compliant"
    seen = {}
    monkeypatch.setattr(comparison, "pick_policy", lambda agent: "policy")
    monkeypatch.setattr(comparison, "run_debridement", lambda policy, *args, **world: seen.update(world) or [])
    comparison.benchmark_debridement(SimpleNamespace(config=rigid), n_trials=1)
    assert seen["contact"] == "rigid" and seen["bias"] == rigid.bias
    comparison.benchmark_debridement(SimpleNamespace(config=TrainConfig(agent="sac_her")), n_trials=1)
    assert seen["contact"] == "compliant"
    notes = comparison.setting_mismatches(
        SimpleNamespace(config=rigid, label="sac_her (5 steps, seed 0)", env_changes={}, source=source_fingerprint()),
        PipelineConfig(),
        picks=True,
    )
    assert notes == ["sac_her (5 steps, seed 0): learnt on the rigid paper and picks on it; the calibrators' picks met the compliant one"]
    assert (
        comparison.setting_mismatches(
            SimpleNamespace(config=TrainConfig(agent="sac_her"), label="x", env_changes={}, source=source_fingerprint()), PipelineConfig()
        )
        == []
    )


def test_a_pick_agent_picks_with_every_keyword_of_its_training_env(monkeypatch):
    """A pick agent's other training keywords (its timing, restored ones included) reach its
    evaluation's env; the protocol's own (fragment, picks, action mode) do not; a GridTouch
    agent's GridTouch keywords have no part in a pick."""
    from dvrk_gym.baselines import comparison

    seen = {}
    monkeypatch.setattr(comparison, "pick_policy", lambda agent: "policy")
    monkeypatch.setattr(comparison, "run_debridement", lambda policy, *args, **world: seen.update(world) or [])
    picker = TrainConfig(agent="sac_pick", env_overrides={"timing": FAST_PICKS, "max_picks": 3, "remove_failed": False})
    comparison.benchmark_debridement(SimpleNamespace(config=picker), n_trials=1)
    assert seen["env_kwargs"] == {"timing": FAST_PICKS, "remove_failed": False} and seen["contact"] == "compliant"
    seen.clear()
    toucher = TrainConfig(agent="sac_her", env_overrides={"distance_threshold_m": 0.002})
    comparison.benchmark_debridement(SimpleNamespace(config=toucher), n_trials=1)
    assert seen["env_kwargs"] == {}


def test_run_debridement_refuses_env_keywords_that_repeat_its_arguments():
    from dvrk_gym.evaluation.trials import run_debridement

    with pytest.raises(ValueError, match=r"repeat run_debridement's own arguments: \['contact'\]"):
        run_debridement(lambda observation: None, n_trials=1, seed=0, env_kwargs={"contact": "rigid"})


def test_trials_on_an_env_without_a_trial_table_are_refused():
    """A GridTouch env, or Debridement in delta mode, gave trials with no outcomes and NaN times."""
    for env_id, kwargs, word in (("dvrk_gym/GridTouch-v0", {}, "GridTouchEnv"), (DEBRIDEMENT_ID, {"action_mode": "delta"}, "'delta' mode")):
        env = gym.make(env_id, camera_resolution=TINY, **kwargs)
        try:
            with pytest.raises(ValueError, match=f"need a Debridement-v0 env in primitive mode, got .*{word}"):
                run_trials(env, lambda observation: np.zeros(4, np.float32), 1, progress=False)
        finally:
            env.close()


def test_n_trials_is_named_as_such(debridement_env):
    with pytest.raises(ValueError, match="n_trials must be an int in"):
        run_trials(debridement_env, lambda observation: debridement_env.action_space.sample(), 0, progress=False)


def test_an_agent_trained_by_other_source_gets_a_note_and_one_of_this_source_none():
    """Only env setting changes were noted: a model made by other simulator code (its recorded
    source fingerprint) was evaluated without a word."""
    from dvrk_gym.baselines import comparison
    from dvrk_gym.calibration.pipeline import PipelineConfig

    def agent(source):
        return SimpleNamespace(config=TrainConfig(agent="sac_her"), label="sac_her (5 steps, seed 0)", env_changes={}, source=source)

    assert comparison.env_change_notes(agent(source_fingerprint())) == []
    other = SourceFingerprint(version="0.0.9", sha256="ab" * 32)
    (note,) = comparison.env_change_notes(agent(other), picks=True)
    assert note.startswith("sac_her (5 steps, seed 0): trained by dvrk_gym 0.0.9, source sha256 abababababab; evaluated with dvrk_gym")
    assert "did not record its source" in comparison.setting_mismatches(agent(None), PipelineConfig())[0]
