"""Reinforcement-learning baselines: learn the correction from reward, for the calibrator's robot moves.

Issue 7 asks how an agent that learns where to send the robot from reward compares with
the two-phase calibrator for the same number of robot moves (5,476: the paper's Phase I
poses and Phase II touches; and ten times that).

- :mod:`~dvrk_gym.baselines.budgets`: the agents' names and envs, and the budgets in env steps (no heavy imports).
- :mod:`~dvrk_gym.baselines.wrappers`: GridTouch-v0 as the agents see it (goals scaled,
  ``(bx, by, bz)`` in [-1, 1], the yaw the episode asks for).
- :mod:`~dvrk_gym.baselines.picking`: Debridement-v0 (one pick per step) as the pick
  agent sees it (the pick target, ``(bx, by, bz)`` in [-1, 1], a shaped reward).
- :mod:`~dvrk_gym.baselines.agents`: the agents, one table row each (SAC + HER, SAC, SAC on picks).
- :mod:`~dvrk_gym.baselines.training`: training with a learning curve.
- :mod:`~dvrk_gym.baselines.checkpoints`: save (SB3 zip + JSON recording the whole env and the zip's
  digest), load without unpickling, in the env the agent learnt in.
- :mod:`~dvrk_gym.baselines.curves`: learning curves as JSON and figures.
- :mod:`~dvrk_gym.baselines.transfer`: any agent as a Debridement-v0 policy (:func:`pick_policy`).
- :mod:`~dvrk_gym.baselines.comparison`: the calibrators' benchmarks (touch grid,
  debridement trials) for agents, and the comparison tables.

The names below are imported on first use, so that importing this package (for the
command line's help, say) does not load torch or pybullet.

Example::

    from dvrk_gym.baselines import TrainConfig, train, save_agent, load_agent, pick_policy

    result = train(TrainConfig(agent="sac_her", steps=5476, seed=0))
    path = save_agent(result, "out/model.zip")
    agent = load_agent(path)  # only files this tool wrote
    policy = pick_policy(agent)  # Debridement-v0 observation -> (bx, by, bz, yaw)
"""

from __future__ import annotations

from dvrk_gym.utils.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(  # PEP 562: each name imported from its module when first asked for
    __name__,
    {
        "AGENTS": "agents",
        "AgentSpec": "agents",
        "build_model": "agents",
        "get_agent": "agents",
        "BUDGETS": "budgets",
        "CALIBRATOR_MOVES": "budgets",
        "resolve_budget": "budgets",
        "LoadedAgent": "checkpoints",
        "load_agent": "checkpoints",
        "save_agent": "checkpoints",
        "CurvePoint": "curves",
        "TrainConfig": "training",
        "TrainResult": "training",
        "train": "training",
        "wrap_grid_touch": "wrappers",
        "wrap_debridement": "picking",
        "pick_policy": "transfer",
    },
)
