"""Reinforcement-learning baselines: learn the correction from reward, for the calibrator's robot moves.

Issue 7 asks how an agent that learns where to send the robot from GridTouch-v0's reward
compares with the two-phase calibrator for the same number of robot moves (5,476: the
paper's Phase I poses and Phase II touches; and ten times that).

- :mod:`~dvrk_gym.baselines.budgets`: the budgets in env steps.
- :mod:`~dvrk_gym.baselines.wrappers`: GridTouch-v0 as the agents see it (goals scaled,
  ``(bx, by, bz)`` in [-1, 1], the yaw the episode asks for).
- :mod:`~dvrk_gym.baselines.agents`: the agents, one table row each (SAC + HER, SAC).
- :mod:`~dvrk_gym.baselines.training`: training with a learning curve.
- :mod:`~dvrk_gym.baselines.checkpoints`: save (SB3 zip + JSON), load without unpickling.
- :mod:`~dvrk_gym.baselines.curves`: learning curves as JSON and figures.
- :mod:`~dvrk_gym.baselines.comparison`: the calibrators' benchmark for agents, and the
  comparison table.

A Debridement agent (PPO or SAC on the pick target in primitive mode) waits for
``dvrk_gym/Debridement-v0``; it will be a row of :data:`~dvrk_gym.baselines.agents.AGENTS`
naming that env id, and a budget in :data:`~dvrk_gym.baselines.budgets.BUDGETS`.

Example::

    from dvrk_gym.baselines import TrainConfig, train, save_agent, load_agent

    result = train(TrainConfig(agent="sac_her", steps=5476, seed=0))
    path = save_agent(result, "out/model.zip")
    agent = load_agent(path)  # only files this tool wrote
"""

from dvrk_gym.baselines.agents import AGENTS, AgentSpec, build_model, get_agent
from dvrk_gym.baselines.budgets import BUDGETS, CALIBRATOR_MOVES, resolve_budget
from dvrk_gym.baselines.checkpoints import LoadedAgent, load_agent, save_agent
from dvrk_gym.baselines.training import CurvePoint, TrainConfig, TrainResult, train
from dvrk_gym.baselines.wrappers import wrap_grid_touch

__all__ = [
    "AGENTS", "AgentSpec", "build_model", "get_agent",
    "BUDGETS", "CALIBRATOR_MOVES", "resolve_budget",
    "LoadedAgent", "load_agent", "save_agent",
    "CurvePoint", "TrainConfig", "TrainResult", "train",
    "wrap_grid_touch",
]
