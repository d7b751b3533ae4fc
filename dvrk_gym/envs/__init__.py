"""Gymnasium environments of the dVRK experiment, registered as ``dvrk_gym/<Name>-v0``.

Each id is registered with the episode length its defaults give as ``max_episode_steps``:
CalibrationExploration-v0 93 poses (one of the paper's Phase I trajectories), Debridement-v0
eight picks (one trial). GridTouch-v0 has none: every episode is one touch, which ends it
(``terminated``); a time limit of one step would also mark that touch ``truncated``, which
it is not. An env also ends its episodes itself
(``max_steps``, ``max_picks``); if you raise those, raise ``max_episode_steps`` with them,
e.g. ``gym.make("dvrk_gym/Debridement-v0", action_mode="delta", max_episode_steps=600)``.
"""

from __future__ import annotations

import gymnasium as gym

from dvrk_gym import paper

ENV_ENTRY_POINTS = {
    "dvrk_gym/CalibrationExploration-v0": "dvrk_gym.envs.exploration:CalibrationExplorationEnv",
    "dvrk_gym/GridTouch-v0": "dvrk_gym.envs.grid_touch:GridTouchEnv",
    "dvrk_gym/Debridement-v0": "dvrk_gym.envs.debridement:DebridementEnv",
}
"""Each env id and the class that implements it."""
EPISODE_STEPS = {
    "dvrk_gym/CalibrationExploration-v0": paper.PHASE1_POSES_PER_TRAJECTORY,
    "dvrk_gym/GridTouch-v0": None,
    "dvrk_gym/Debridement-v0": paper.FRAGMENTS_PER_TRIAL,
}
"""Steps of one episode with each env's defaults, for Gymnasium's TimeLimit (None: the env always
terminates its episodes itself); a test checks them against the configs."""


def register_envs() -> None:
    """Register every environment with Gymnasium (idempotent)."""
    for env_id, entry_point in ENV_ENTRY_POINTS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point, max_episode_steps=EPISODE_STEPS[env_id])
