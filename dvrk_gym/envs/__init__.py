"""Gymnasium environments of the dVRK experiment, registered as ``dvrk_gym/<Name>-v0``."""

from __future__ import annotations

import gymnasium as gym

ENV_ENTRY_POINTS = {
    "dvrk_gym/CalibrationExploration-v0": "dvrk_gym.envs.exploration:CalibrationExplorationEnv",
    "dvrk_gym/GridTouch-v0": "dvrk_gym.envs.grid_touch:GridTouchEnv",
    "dvrk_gym/Debridement-v0": "dvrk_gym.envs.debridement:DebridementEnv",
}


def register_envs() -> None:
    """Register every environment with Gymnasium (idempotent)."""
    for env_id, entry_point in ENV_ENTRY_POINTS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)
