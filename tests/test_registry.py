"""The registry: every id carries its config's defaults as ``kwargs`` (plain JSON values), and
``gym.make`` validates what it is given, for all three envs."""

import dataclasses
import importlib
import json

import gymnasium as gym
import numpy as np
import pytest
from conftest import SMALL, json_from_fresh_process
from gymnasium.envs.registration import EnvSpec

import dvrk_gym
from dvrk_gym.envs import ENV_CONFIGS

ALL_IDS = list(dvrk_gym.ENV_IDS)


def _env_class(env_id: str) -> type:
    module, _, name = gym.spec(env_id).entry_point.partition(":")
    return getattr(importlib.import_module(module), name)


def _plain(value):
    """A default as JSON holds it: tuples as lists, nested configs as dicts."""
    if dataclasses.is_dataclass(value):
        return {field.name: _plain(getattr(value, field.name)) for field in dataclasses.fields(value)}
    if isinstance(value, tuple):
        return [_plain(item) for item in value]
    return value


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_spec_kwargs_are_every_config_default_as_plain_json(env_id):
    config_class = _env_class(env_id).config_class
    assert ENV_CONFIGS[env_id] is config_class
    kwargs = gym.spec(env_id).kwargs
    defaults = config_class()
    assert list(kwargs) == [field.name for field in dataclasses.fields(config_class)]
    for name, value in kwargs.items():
        assert value == _plain(getattr(defaults, name)), name
    assert json.loads(json.dumps(kwargs)) == kwargs  # plain JSON: nothing a round trip changes
    assert EnvSpec.from_json(gym.spec(env_id).to_json()) == gym.spec(env_id)
    assert config_class(**kwargs) == defaults  # the config reads them back as its defaults


def test_spec_kwargs_hold_the_settings_people_look_for():
    assert gym.spec("dvrk_gym/GridTouch-v0").kwargs["camera_resolution"] == [1920, 1080]
    assert gym.spec("dvrk_gym/GridTouch-v0").kwargs["reward_type"] == "dense"
    assert gym.spec("dvrk_gym/CalibrationExploration-v0").kwargs["max_steps"] == 93
    debridement = gym.spec("dvrk_gym/Debridement-v0").kwargs
    assert debridement["max_picks"] == 8 and debridement["gripper"]["jaw_friction"] == 1.5
    assert debridement["timing"]["travel"]["max_speed_m_s"] == 0.065


def test_the_registry_is_read_without_loading_pybullet_or_scipy():
    code = (
        "import json, sys, gymnasium as gym, dvrk_gym\n"
        "kwargs = gym.spec('dvrk_gym/Debridement-v0').kwargs\n"
        "print(json.dumps([len(kwargs), sorted(m for m in ('pybullet', 'scipy', 'torch') if m in sys.modules)]))\n"
    )
    assert json_from_fresh_process(code) == [len(dataclasses.fields(ENV_CONFIGS["dvrk_gym/Debridement-v0"])), []]


def _first_steps(env, seed: int, n: int) -> list[float]:
    observation, _ = env.reset(seed=seed)
    values = [float(v) for key in sorted(observation) for v in np.ravel(observation[key])]
    actions = np.random.default_rng(seed)
    for _ in range(n):
        action = actions.uniform(env.action_space.low, env.action_space.high)
        observation, reward, terminated, truncated, _ = env.step(action)
        values += [float(reward)] + [float(v) for key in sorted(observation) for v in np.ravel(observation[key])]
        if terminated or truncated:  # a GridTouch touch ends its episode: the next one goes on from it
            observation, _ = env.reset()
            values += [float(v) for key in sorted(observation) for v in np.ravel(observation[key])]
    return values


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gym_make_with_the_spec_kwargs_is_the_env_its_class_makes_with_no_keywords(env_id):
    spec_kwargs = {**gym.spec(env_id).kwargs, "camera_resolution": list(SMALL)}
    made = gym.make(env_id, **spec_kwargs)
    direct = _env_class(env_id)(camera_resolution=SMALL)  # the class's own defaults, no registry
    try:
        assert made.unwrapped.config == direct.config
        steps = 0 if env_id == "dvrk_gym/Debridement-v0" else 2  # a Debridement step is a whole pick
        assert _first_steps(made.unwrapped, seed=3, n=steps) == _first_steps(direct, seed=3, n=steps)
    finally:
        made.close()
        direct.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gym_make_refuses_an_unknown_keyword_naming_the_ones_it_takes(env_id):
    named = r"unexpected keyword argument 'bias_sed' \(did you mean 'bias_seed'\?\); its keywords are: .*camera_resolution"
    with pytest.raises(TypeError, match=named):
        gym.make(env_id, bias_sed=3)
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'colour'; its keywords are: "):
        _env_class(env_id)(colour="red")


@pytest.mark.parametrize(
    ("env_id", "kwargs", "words"),
    [
        ("dvrk_gym/GridTouch-v0", {"bias_seed": -1}, r"bias_seed must be .*0"),
        ("dvrk_gym/GridTouch-v0", {"camera_resolution": [0, 360]}, "camera_resolution"),
        ("dvrk_gym/GridTouch-v0", {"reward_type": "shaped"}, r"reward_type must be one of \['dense', 'sparse'\]"),
        ("dvrk_gym/GridTouch-v0", {"distance_threshold_m": float("nan")}, "distance_threshold_m"),
        ("dvrk_gym/CalibrationExploration-v0", {"max_steps": 0}, "max_steps"),
        ("dvrk_gym/CalibrationExploration-v0", {"bias": "rusty"}, r"bias must be one of \['none', 'paper', 'severe'\]"),
        ("dvrk_gym/Debridement-v0", {"fragment": "almond"}, r"fragment must be one of \['pumpkin_seed', 'raisin'\]"),
        ("dvrk_gym/Debridement-v0", {"timing": {"grip_dwel_s": 1.0}}, "bad timing or gripper settings: .*'grip_dwel_s'"),
        ("dvrk_gym/Debridement-v0", {"gripper": {"grip_force_n": -1.0}}, "grip_force_n"),
    ],
)
def test_gym_make_refuses_a_bad_value_saying_what_is_allowed(env_id, kwargs, words):
    with pytest.raises(ValueError, match=words):
        gym.make(env_id, **kwargs)
