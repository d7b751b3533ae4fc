"""Behaviour every environment shares: API conformance, seeding, strict inputs, vector envs (all three envs;
three tests leave out Debridement-v0, whose own tests run them in both its action modes)."""

import dataclasses
import importlib
import inspect
import json
import warnings

import gymnasium as gym
import numpy as np
import pybullet
import pytest
from conftest import ENV_IDS, ENV_IDS_BUT_DEBRIDEMENT, SMALL, json_from_fresh_process
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env


def _rollout(env, seed: int, n: int, action_seed: int = 123, keep_history: bool = False, before_step=None):
    """Reset with ``seed`` (keeping the cable history if asked and the env has the
    option), then ``n`` steps of seeded random actions, resetting without a seed (the
    history carries) after each episode; ``before_step()`` is called before each step."""
    actions = np.random.default_rng(action_seed)
    space = env.action_space
    observations = []
    options = {"relax": False} if keep_history and "relax" in env.unwrapped.option_names else None
    obs, _ = env.reset(seed=seed, options=options)
    observations.append(obs)
    for _ in range(n):
        action = actions.uniform(space.low, space.high).astype(np.float32)
        if before_step is not None:
            before_step()
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        if terminated or truncated:
            obs, _ = env.reset()
            observations.append(obs)
    return observations


def _flatten(observations) -> list[float]:
    return [float(v) for obs in observations for key in sorted(obs) for v in np.ravel(obs[key])]


@pytest.mark.parametrize("env_id", ENV_IDS_BUT_DEBRIDEMENT)
def test_passes_gymnasium_and_sb3_checkers(make_env, env_id):
    env = make_env(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # both checkers advise a [-1, 1] action box; ours is SI
        check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_and_actions_give_bit_identical_observations(make_env, env_id):
    env = make_env(env_id)
    first = _flatten(_rollout(env, seed=7, n=4))
    _rollout(env, seed=99, n=3)  # something else in between
    second = _flatten(_rollout(env, seed=7, n=4))  # a seeded reset relaxes the cables
    assert first == second


@pytest.mark.parametrize("env_id", ENV_IDS_BUT_DEBRIDEMENT)
def test_same_seed_and_same_cable_history_give_bit_identical_observations(make_env, env_id):
    a, b = make_env(env_id), make_env(env_id)
    for env in (a, b):
        _rollout(env, seed=99, n=3)  # the same history on both
    kept = _flatten(_rollout(a, seed=7, n=4, keep_history=True))
    assert kept == _flatten(_rollout(b, seed=7, n=4, keep_history=True))
    if "relax" in a.unwrapped.option_names:  # and the history matters
        assert kept != _flatten(_rollout(a, seed=7, n=4))


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS_BUT_DEBRIDEMENT)
def test_observations_are_identical_across_processes(make_env, env_id):
    here = _flatten(_rollout(make_env(env_id), seed=3, n=3))
    code = (
        "import json, gymnasium as gym, dvrk_gym, test_envs_common as t\n"
        f"env = gym.make({env_id!r}, camera_resolution={SMALL!r})\n"
        "print(json.dumps(t._flatten(t._rollout(env, seed=3, n=3))))\n"
    )
    there = json_from_fresh_process(code)
    assert here == there


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_different_seeds_give_different_episodes(make_env, env_id):
    env = make_env(env_id)
    assert _flatten(_rollout(env, seed=1, n=2)) != _flatten(_rollout(env, seed=2, n=2))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_step_before_reset_is_a_clear_error(make_env, env_id):
    env = make_env(env_id).unwrapped
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(env.action_space.sample())


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_names_the_element_and_leaves_the_world_intact(make_env, env_id, bad):
    env = make_env(env_id).unwrapped
    env.reset(seed=0)
    action = env.action_space.sample()
    action[2] = bad
    with pytest.raises(ValueError, match=r"action\[2\] \(bz\)"):
        env.step(action)
    obs, *_ = env.step(env.action_space.sample())  # the world still works
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_wrong_action_shape_is_a_clear_error(make_env, env_id):
    env = make_env(env_id).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(9))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_out_of_range_action_is_clamped_and_reported(make_env, env_id):
    env = make_env(env_id).unwrapped
    env.reset(seed=0)
    action = env.action_space.sample()
    action[0] = 5.0  # five metres: far outside the space
    obs, _, _, _, info = env.step(action)
    assert "bx" in info["clamped"]
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_unknown_reset_option_lists_the_valid_ones(make_env, env_id):
    env = make_env(env_id).unwrapped
    with pytest.raises(ValueError, match="unknown reset option.*valid options"):
        env.reset(seed=0, options={"colour": "red"})


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_unknown_constructor_argument_and_bias_preset_are_clear_errors(env_id):
    with pytest.raises(TypeError, match="unexpected keyword argument 'biass'"):
        gym.make(env_id, camera_resolution=SMALL, biass="paper")
    with pytest.raises(ValueError, match="paper"):
        gym.make(env_id, camera_resolution=SMALL, bias="no-such-preset")


def test_a_subclass_that_inherits_the_constructor_is_named_in_its_refusal():
    from dvrk_gym.envs.grid_touch import GridTouchEnv

    class ShapedGridTouch(GridTouchEnv):
        pass

    with pytest.raises(TypeError, match=r"^ShapedGridTouch got an unexpected keyword argument 'biass' \(did you mean 'bias'\?\)"):
        ShapedGridTouch(camera_resolution=SMALL, biass="paper")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_render_modes(make_env, env_id):
    env = make_env(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (SMALL[1], SMALL[0], 3) and frame.dtype == np.uint8
    quiet = make_env(env_id)
    quiet.reset(seed=0)
    assert quiet.render() is None
    with pytest.raises(ValueError, match="render_mode"), pytest.warns(UserWarning, match="render_mode='movie'"):
        gym.make(env_id, render_mode="movie")  # gymnasium warns, then the env refuses


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_human_render_mode_without_display_warns_and_runs_without_a_window(env_id, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.warns(RuntimeWarning, match="DISPLAY is not set"):
        env = gym.make(env_id, render_mode="human", camera_resolution=SMALL)
    try:
        env.reset(seed=0)
        assert env.render() is None
        assert env.unwrapped.world.physics.client.getConnectionInfo()["connectionMethod"] == pybullet.DIRECT
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_metadata_is_class_level_and_not_mutated(make_env, env_id):
    env = make_env(env_id)
    cls = type(env.unwrapped)
    before = json.dumps(cls.metadata, sort_keys=True)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    assert json.dumps(cls.metadata, sort_keys=True) == before
    assert "metadata" not in vars(env.unwrapped)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_envs_work(env_id, mode):
    envs = gym.make_vec(env_id, num_envs=4, vectorization_mode=mode, camera_resolution=SMALL)
    try:
        obs, _ = envs.reset(seed=0)
        for _ in range(2):
            obs, rewards, terminated, truncated, _ = envs.step(envs.action_space.sample())
        assert rewards.shape == (4,)
        assert all(np.all(np.isfinite(v)) for v in obs.values())
    finally:
        envs.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_truth_is_only_in_info(make_env, env_id):
    env = make_env(env_id, bias="paper")
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    obs, _, _, _, info = env.step(env.action_space.sample())
    truths = {k: v for k, v in info.items() if k.startswith("true_")}
    assert truths, "info must carry the truth under true_* names"
    assert not any("true" in key for key in obs)
    flat = np.concatenate([np.ravel(v).astype(float) for v in obs.values()])
    for name, value in truths.items():
        for component in np.ravel(value):
            if component == 0.0:  # an exact zero is a placeholder (an empty slot, a fragment taken away), not a measurement
                continue
            assert not np.any(np.abs(flat - component) < 1e-7), f"{name} leaks into the observation"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_two_envs_in_one_process_are_independent(make_env, env_id):
    a, b = make_env(env_id), make_env(env_id)
    reference = _flatten(_rollout(a, seed=5, n=2))
    b.reset(seed=11)
    b.action_space.seed(11)

    def b_steps() -> None:  # between a's seeded reset and each of a's steps, where state they shared would show
        *_, terminated, truncated, _ = b.step(b.action_space.sample())
        if terminated or truncated:
            b.reset()

    assert _flatten(_rollout(a, seed=5, n=2, before_step=b_steps)) == reference
    a.close()
    b.reset(seed=1)  # b survives a's close
    obs, *_ = b.step(b.action_space.sample())
    assert b.observation_space.contains(obs)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_constructor_keywords_are_the_config_fields_with_the_same_defaults_and_docs(env_id):
    env_class = gym.spec(env_id).entry_point
    module, _, name = env_class.partition(":")
    env_class = getattr(importlib.import_module(module), name)
    parameters = inspect.signature(env_class).parameters
    config_fields = {field.name: field for field in dataclasses.fields(env_class.config_class)}
    keywords = {n: p for n, p in parameters.items() if p.kind is inspect.Parameter.KEYWORD_ONLY}
    assert sorted(keywords) == sorted(config_fields)
    defaults = env_class.config_class()
    for field_name, parameter in keywords.items():
        assert parameter.annotation != inspect.Parameter.empty, field_name
        assert parameter.default == getattr(defaults, field_name), field_name
        assert f"{field_name}:" in env_class.__init__.__doc__, f"{field_name} is not documented in help()"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_no_env_is_registered_with_a_time_limit(env_id):
    # the exploration env truncates after max_steps; one touch terminates GridTouch's episode;
    # a trial terminates after max_picks picks, and delta mode truncates after max_steps
    assert gym.spec(env_id).max_episode_steps is None


@pytest.mark.parametrize("max_steps", [5, 120])
def test_the_exploration_envs_max_steps_alone_sets_its_episode_length(max_steps):
    """A registered limit of 93 cut max_steps=120 at 93 poses, silently."""
    env = gym.make("dvrk_gym/CalibrationExploration-v0", camera_resolution=SMALL, max_steps=max_steps)
    try:
        env.reset(seed=0)
        env.action_space.seed(0)
        steps, truncated, terminated = 0, False, False
        while not (truncated or terminated):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            steps += 1
        assert (steps, terminated, truncated) == (max_steps, False, True)
    finally:
        env.close()


def test_debridement_ends_its_own_episodes_in_both_modes():
    """The registry sets no time limit: a primitive trial ends terminated (not truncated)
    after max_picks picks, and a delta-mode episode runs past eight steps to max_steps."""
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=SMALL, max_picks=2)
    try:
        env.reset(seed=0)
        ends = [env.step(np.array([0.03, 0.04, -0.15, 0.0], dtype=np.float32))[2:4] for _ in range(2)]
    finally:
        env.close()
    assert ends == [(False, False), (True, False)]
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=SMALL, action_mode="delta", max_steps=12)
    try:
        env.reset(seed=0)
        ends = [env.step(np.zeros(4, dtype=np.float32))[2:4] for _ in range(12)]
    finally:
        env.close()
    assert ends[:11] == [(False, False)] * 11 and ends[11] == (False, True)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_env_checker_passes_without_flags_headless_with_rendering(env_id, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    env = gym.make(env_id, camera_resolution=SMALL, render_mode="rgb_array")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the checker advises a [-1, 1] action box; ours is SI
            check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_env_reports_is_success_at_the_end_of_an_episode(make_env, env_id):
    env = make_env(env_id)
    env.reset(seed=0)
    done, info = False, {}
    while not done:
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        done = terminated or truncated
    assert isinstance(info["is_success"], (bool, np.bool_))


@pytest.mark.slow
@pytest.mark.parametrize("vectorization_mode", ["sync", "async"])
def test_make_vec_steps_every_env_in_sync_and_async_vector_envs(vectorization_mode):
    for env_id in ENV_IDS:
        envs = gym.make_vec(env_id, num_envs=2, vectorization_mode=vectorization_mode, camera_resolution=SMALL)
        try:
            observations, _ = envs.reset(seed=[3, 4])
            observations, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
            assert rewards.shape == (2,) and terminated.shape == (2,)
        finally:
            envs.close()


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_record_video_writes_an_episode_of_every_env(env_id, tmp_path):
    pytest.importorskip("moviepy")
    from gymnasium.wrappers import RecordVideo

    folder = tmp_path / "videos"  # a folder RecordVideo makes: it warns when it overwrites one that exists
    env = RecordVideo(gym.make(env_id, camera_resolution=(256, 144), render_mode="rgb_array"), str(folder), episode_trigger=lambda _: True)
    try:
        env.reset(seed=0)
        env.action_space.seed(0)
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            done = terminated or truncated
    finally:
        env.close()
    videos = list(folder.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0


def test_debridement_renders_the_frames_of_a_pick_phase_by_phase():
    env = gym.make("dvrk_gym/Debridement-v0", camera_resolution=(160, 90), render_mode="rgb_array_list")
    try:
        env.reset(seed=0)
        assert len(env.render()) == 1  # the table as the episode starts
        env.step(env.action_space.sample())
        frames = env.render()
        assert len(frames) == 6 and all(frame.shape == (90, 160, 3) for frame in frames)  # the paper's six phases
        assert env.render() == []  # each frame is handed out once
        assert not all(np.array_equal(frames[0], frame) for frame in frames[1:])  # the arm moved
    finally:
        env.close()
