"""Shared fixtures: small images keep the env tests fast; full-HD tests ask for it."""

import gymnasium as gym
import pytest

import dvrk_gym  # noqa: F401  (registers the environments)

SMALL = (640, 360)
ENV_IDS = ["dvrk_gym/CalibrationExploration-v0", "dvrk_gym/GridTouch-v0"]


@pytest.fixture
def make_env():
    """Make environments that are closed after the test."""
    made = []

    def _make(env_id: str, **kwargs):
        kwargs.setdefault("camera_resolution", SMALL)
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()
