"""Trained agents as Debridement-v0 policies: observation dict in, pick ``(bx, by, bz, yaw)`` out.

A GridTouch-v0 agent learnt "camera-frame target -> base-frame command that touches it",
which is what a pick needs, just as the calibrator fitted to calibration data is used for
debridement. :func:`pick_policy` feeds it the pick target the calibrated policy uses
(:func:`~dvrk_gym.envs.debridement.fragment_target`: the first fragment seen, and the
image rule's yaw rounded to the nearest paper yaw, as ``CalibratedPolicy`` rounds it) as
GridTouch's desired goal, with the rest of GridTouch's observation as at the start of a
touch (the robot at its home pose; the yaw replaced by the pick's). The agent's action is
mapped onto the base-frame box as in training; Debridement's pick box is GridTouch's.

The paper is the same in both envs (:mod:`dvrk_gym.sim.table.contact`): a GridTouch touch
sent under it goes on down and its jaws slide along it, and a pick's jaws, lowered onto it,
stall on a floor just above it and slide by as much for a command as deep under the paper. A
GridTouch agent that learnt to send its touches deep and aim against the slide therefore
picks near where it touched: a pick closes its jaws ``grip_depth_m`` (2 mm) under the
command, so it goes that much deeper than the touch and slides about 1.5 mm further.
(With GridTouch's paper compliant and the picks' rigid, as before the picks slid, the
agents' deep, slide-aimed commands missed most fragments: the README.)

A pick agent (Debridement-v0) gets the same raw-observation interface, through the
functions its training wrapper uses.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dvrk_gym.baselines.budgets import DEBRIDEMENT_ID, GRID_TOUCH_ID
from dvrk_gym.baselines.checkpoints import LoadedAgent
from dvrk_gym.baselines.picking import pick_action, pick_observation, pick_yaw
from dvrk_gym.baselines.training import make_agent_env
from dvrk_gym.baselines.wrappers import scale_goal
from dvrk_gym.envs.debridement import fragment_target

HOME_RESET_SEED = 0
"""Seed of the GridTouch reset that gives the home observation a transferred agent sees."""


class GridTouchPickPolicy:
    """A GridTouch-v0 agent aiming Debridement-v0's picks (see the module).

    Args:
        agent: an agent trained on GridTouch-v0 (``sac_her``, ``sac``).

    Raises:
        ValueError: the agent learnt another env.
    """

    def __init__(self, agent: LoadedAgent) -> None:
        if agent.config.spec.env_id != GRID_TOUCH_ID:
            raise ValueError(f"{agent.label} learnt {agent.config.spec.env_id}; GridTouchPickPolicy needs an agent of {GRID_TOUCH_ID}")
        self.agent = agent
        env = make_agent_env(agent.config, training=False)
        try:
            self.home, _ = env.reset(seed=HOME_RESET_SEED, options={"yaw": 0.0})
        finally:
            env.close()

    def agent_observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The GridTouch observation (scaled goals) the agent is shown for a Debridement observation."""
        position, _ = fragment_target(observation)
        state = self.home["observation"].copy()
        state[-1] = pick_yaw(observation)
        return {"observation": state, "achieved_goal": self.home["achieved_goal"].copy(), "desired_goal": scale_goal(position)}

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        action, _ = self.agent.model.predict(self.agent_observation(observation), deterministic=True)
        return pick_action(action, pick_yaw(observation))


class PickAgentPolicy:
    """A pick agent (trained on Debridement-v0) on the raw Debridement-v0 observation."""

    def __init__(self, agent: LoadedAgent) -> None:
        if agent.config.spec.env_id != DEBRIDEMENT_ID:
            raise ValueError(f"{agent.label} learnt {agent.config.spec.env_id}; PickAgentPolicy needs an agent of {DEBRIDEMENT_ID}")
        self.agent = agent

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        action, _ = self.agent.model.predict({"observation": pick_observation(observation)}, deterministic=True)
        return pick_action(action, pick_yaw(observation))


def pick_policy(agent: LoadedAgent) -> Any:
    """A Debridement-v0 (primitive mode) policy from a loaded agent: observation dict -> (bx, by, bz, yaw).

    GridTouch-v0 agents are transferred (:class:`GridTouchPickPolicy`); pick agents act as
    trained (:class:`PickAgentPolicy`). Works with :func:`dvrk_gym.evaluation.episodes.run_episodes`
    and :func:`dvrk_gym.evaluation.trials.run_trials`.

    Raises:
        ValueError: the agent learnt an env that is neither.
    """
    env_id = agent.config.spec.env_id
    if env_id == GRID_TOUCH_ID:
        return GridTouchPickPolicy(agent)
    if env_id == DEBRIDEMENT_ID:
        return PickAgentPolicy(agent)
    raise ValueError(f"{agent.label} learnt {env_id}; pick_policy handles agents of {GRID_TOUCH_ID} and {DEBRIDEMENT_ID}")
