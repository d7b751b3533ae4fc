"""The reinforcement-learning agents, one table row each: env id, algorithm, wrappers, settings.

An agent is named by an :class:`AgentSpec`: which environment it learns, with which
stable-baselines3 algorithm and replay buffer, through which wrapper, with which env
keywords and hyperparameters. Adding an agent is adding a row to :data:`AGENTS` (and its
name, env and description to :mod:`dvrk_gym.baselines.budgets`). Two agents learn
GridTouch-v0 (one touch per step), one learns Debridement-v0 in primitive mode (one pick
per step); a budget counts env steps of either, i.e. robot moves.

:func:`check_policy_kwargs` bounds the networks an agent file's settings may describe,
before anything is built (:mod:`dvrk_gym.baselines.checkpoints` reads those files).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.her import HerReplayBuffer

from dvrk_gym.baselines.budgets import AGENT_DESCRIPTIONS, AGENT_ENVS
from dvrk_gym.baselines.picking import wrap_debridement
from dvrk_gym.baselines.wrappers import wrap_grid_touch
from dvrk_gym.utils.checks import check_bool, check_int

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"SAC": SAC, "TD3": TD3, "PPO": PPO}
MAX_LAYERS = 16
MAX_LAYER_UNITS = 4096
"""Bounds of the networks an agent file's settings may describe: hidden layers, and units per layer."""
MAX_POLICY_PARAMETERS = 2**25
"""The most weights (about 128 MB of float32) that the networks of an agent file's settings may hold
together, counted before any is built (a 256 x 256 SAC's: about 0.4 million)."""
_IO_UNITS = 64
"""Units counted for a network's input and output layers: more than any agent's observation
or action has, so the count is an upper bound."""
_POLICY_KEYS = {"net_arch", "use_sde", "n_critics"}


@dataclass(frozen=True)
class AgentSpec:
    """One agent.

    Attributes:
        name: the agent's name on the command line.
        env_id: the Gymnasium id it learns.
        algorithm: a key of :data:`ALGORITHMS`.
        her: relabel goals with HER (goal selection "future").
        wrap: ``wrap(env, training_yaws)`` gives the env as the agent sees it
            (``training_yaws`` is None for evaluation).
        description: one line for help texts and tables.
        env_kwargs: keywords for ``gym.make`` (the reward's form, say).
        hyperparameters: keywords for the algorithm's constructor.
    """

    name: str
    env_id: str
    algorithm: str
    her: bool
    wrap: Callable[[gym.Env, str | None], gym.Env]
    description: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    hyperparameters: dict[str, Any] = field(default_factory=dict)


_GRID_TOUCH_SAC = {
    "learning_rate": 1e-3,
    "buffer_size": 100_000,
    "batch_size": 256,
    "learning_starts": 200,
    "train_freq": 1,
    "gradient_steps": 4,  # updates per robot move: 1, 2, 4 gave 1.28, 0.91, 0.73 mm after 2,000 moves
    "policy_kwargs": {"net_arch": [256, 256]},
}

_PICK_SAC = {
    **_GRID_TOUCH_SAC,
    "learning_starts": 100,  # random picks over the workspace (a pick is about 0.5 s of simulation)
    "gamma": 0.0,  # each pick is judged on its own: the next fragment does not depend on this pick's aim
}


def _sac(
    name: str, her: bool, wrap: Callable[[gym.Env, str | None], gym.Env], env_kwargs: dict[str, Any], hyperparameters: dict[str, Any]
) -> AgentSpec:
    """A SAC row; its env and description come from :mod:`dvrk_gym.baselines.budgets`."""
    return AgentSpec(name, AGENT_ENVS[name], "SAC", her, wrap, AGENT_DESCRIPTIONS[name], env_kwargs, hyperparameters)


AGENTS: dict[str, AgentSpec] = {
    "sac_her": _sac("sac_her", True, wrap_grid_touch, {"reward_type": "dense"}, _GRID_TOUCH_SAC),
    "sac": _sac("sac", False, wrap_grid_touch, {"reward_type": "dense"}, _GRID_TOUCH_SAC),
    "sac_pick": _sac("sac_pick", False, wrap_debridement, {"fragment": "pumpkin_seed", "action_mode": "primitive"}, _PICK_SAC),
}
if set(AGENTS) != set(AGENT_DESCRIPTIONS):
    raise RuntimeError(f"budgets.py lists {sorted(AGENT_DESCRIPTIONS)} but AGENTS has {sorted(AGENTS)}")


def get_agent(name: str) -> AgentSpec:
    """The agent called ``name``; a clear error listing the agents otherwise."""
    if name not in AGENTS:
        raise ValueError(f"unknown agent {name!r}; valid: {sorted(AGENTS)}")
    return AGENTS[name]


def build_model(spec: AgentSpec, env: VecEnv, *, seed: int, overrides: dict[str, Any] | None = None, device: str = "cpu") -> BaseAlgorithm:
    """A fresh, seeded model of ``spec`` on ``env`` (``overrides`` replace hyperparameters).

    With ``env.num_envs`` > 1, an off-policy agent's ``gradient_steps`` (per vector-env
    step) is multiplied by ``num_envs``, so that it makes the same number of gradient
    updates per robot move whatever the number of envs.
    """
    kwargs = copy.deepcopy({**spec.hyperparameters, **(overrides or {})})  # SB3 edits policy_kwargs in place
    if "gradient_steps" in kwargs and kwargs["gradient_steps"] > 0:
        kwargs["gradient_steps"] *= env.num_envs
    if spec.her:
        kwargs.setdefault("replay_buffer_class", HerReplayBuffer)
        kwargs.setdefault("replay_buffer_kwargs", {"n_sampled_goal": 4, "goal_selection_strategy": "future"})
    algorithm = ALGORITHMS[spec.algorithm]
    model = algorithm("MultiInputPolicy", env, seed=seed, device=device, verbose=0, **kwargs)
    model.set_logger(silent_logger())
    return model


def silent_logger() -> Logger:
    """A logger that writes nothing and creates no folder (SB3's default makes ``/tmp/SB3-<date>``)."""
    return Logger(folder=None, output_formats=[])


def _check_layers(name: str, layers: Any) -> None:
    if not isinstance(layers, list) or len(layers) > MAX_LAYERS:
        raise ValueError(f"{name} must be a list of at most {MAX_LAYERS} layer sizes, got {layers!r}")
    for i, units in enumerate(layers):
        check_int(f"{name}[{i}]", units, 1, MAX_LAYER_UNITS)


def check_policy_kwargs(kwargs: Any) -> dict[str, Any]:
    """The policy settings of an agent file, if they describe a network within fixed bounds.

    Allowed: ``net_arch`` (a list of at most MAX_LAYERS sizes of 1-MAX_LAYER_UNITS units, or
    ``{"pi": [...], "qf": [...]}``/``{"pi": [...], "vf": [...]}`` of such lists), ``use_sde``
    (bool), ``n_critics`` (1-10).

    Raises:
        ValueError: anything else (the message names the key and what is allowed).
    """
    if not isinstance(kwargs, dict) or not set(kwargs) <= _POLICY_KEYS:
        raise ValueError(f"policy_kwargs must be an object with keys among {sorted(_POLICY_KEYS)}, got {kwargs!r}")
    arch = kwargs.get("net_arch", [])
    if isinstance(arch, dict):
        if not arch or not set(arch) <= {"pi", "qf", "vf"}:
            raise ValueError(f"net_arch must be a list or an object with keys among ['pi', 'qf', 'vf'], got {arch!r}")
        for key, layers in arch.items():
            _check_layers(f"net_arch[{key!r}]", layers)
    else:
        _check_layers("net_arch", arch)
    if "use_sde" in kwargs:
        check_bool("use_sde", kwargs["use_sde"])
    if "n_critics" in kwargs:
        check_int("n_critics", kwargs["n_critics"], 1, 10)
    parameters = policy_parameters_bound(arch, kwargs.get("n_critics", 2))
    if parameters > MAX_POLICY_PARAMETERS:
        raise ValueError(
            f"policy_kwargs describe networks of up to {parameters:,} weights, more than {MAX_POLICY_PARAMETERS:,} "
            f"(net_arch {arch!r}); refused before building them"
        )
    return kwargs


def policy_parameters_bound(arch: list[int] | dict[str, list[int]], n_critics: int) -> int:
    """An upper bound on the weights of an actor-critic's networks with hidden layers ``arch``:
    the actor and ``n_critics`` critics, each with a target copy, inputs and outputs of
    :data:`_IO_UNITS` units."""

    def one(layers: list[int]) -> int:
        sizes = [_IO_UNITS, *layers, _IO_UNITS]
        return sum(a * b + b for a, b in zip(sizes, sizes[1:]))

    if isinstance(arch, dict):  # SAC and TD3 build "qf" critics, PPO a "vf" value network: both counted
        return 2 * one(arch.get("pi", [])) + 2 * n_critics * (one(arch.get("qf", [])) + one(arch.get("vf", [])))
    return 2 * one(arch) + 2 * n_critics * one(arch)
