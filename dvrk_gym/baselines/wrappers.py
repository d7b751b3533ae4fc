"""Wrappers that put GridTouch-v0 in the form the stable-baselines3 agents learn best from.

The agent's action is the base-frame position command ``(bx, by, bz)`` scaled to [-1, 1]
(:class:`TargetYawAction`, then gymnasium's ``RescaleAction``, which maps -1 and +1 to
the bounds of GridTouch's box, metres): the yaw is the one the
episode asks for, as with the calibrators, since the reward does not depend on it and an
agent free to pick its yaw would make the benchmark's yaw settings meaningless. The goals
are scaled from metres to about [-1, 1] over the workspace (:class:`GoalScaling`), so that
a millimetre is a visible change to the networks; the wrapper's ``compute_reward`` undoes
the scaling, so HER's relabelled rewards stay the env's own. :class:`TrainingYaws` chooses
the yaw of each training episode, and :class:`TourStart` where a training sub-env's tour of
the circles begins.
"""

from __future__ import annotations

from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.wrappers import RescaleAction
from numpy.typing import ArrayLike

from dvrk_gym import paper
from dvrk_gym.envs.grid_touch import N_CIRCLES, TOUR
from dvrk_gym.sim.robot.kinematics import PAPER_YAWS_RAD
from dvrk_gym.utils.checks import check_int

GOAL_CENTER_M = (0.0, 0.0, paper.ENDOSCOPE_HEIGHT_M)
"""Camera-frame point mapped to 0 by :class:`GoalScaling`: about the phantom's centre, the endoscope's height away, metres."""
GOAL_HALF_RANGE_M = 0.05
"""Camera-frame distance mapped to 1 by :class:`GoalScaling`, metres (the phantom is 75 mm wide)."""
TRAINING_YAWS = ("paper", "random")
"""How training episodes choose their yaw: a tour of the 35 circles per paper yaw, or a random yaw each."""


def scale_goal(goal_m: np.ndarray, center_m: ArrayLike = GOAL_CENTER_M, half_range_m: float = GOAL_HALF_RANGE_M) -> np.ndarray:
    """Camera-frame points (..., 3) in metres to ``(goal - center) / half_range`` (float32)."""
    return ((np.asarray(goal_m, dtype=np.float64) - np.asarray(center_m, dtype=np.float64)) / half_range_m).astype(np.float32)


class TargetYawAction(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Action ``(bx, by, bz)`` in metres; the yaw (rad) is the one the episode asks for.

    The yaw is read from the last observation (``observation[-1]`` of GridTouch-v0).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        box = env.action_space
        if not isinstance(box, spaces.Box):
            raise TypeError(f"TargetYawAction wraps a Box action space, got {box}")
        self.action_space = spaces.Box(box.low[:3], box.high[:3], dtype=cast(Any, box.dtype))
        self._yaw = 0.0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self._yaw = float(observation["observation"][-1])
        return observation, info

    def action(self, action: np.ndarray) -> np.ndarray:
        return np.append(np.asarray(action, dtype=np.float32), np.float32(self._yaw))


class GoalScaling(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Goals mapped from camera-frame metres to ``(goal - center) / half_range``.

    Args:
        env: a goal-conditioned env (Dict observation with ``achieved_goal`` and
            ``desired_goal``, and ``compute_reward``).
        center_m: the camera-frame point mapped to 0, (x, y, z) metres.
        half_range_m: the distance mapped to 1, metres.
    """

    def __init__(self, env: gym.Env, center_m: tuple[float, float, float] = GOAL_CENTER_M, half_range_m: float = GOAL_HALF_RANGE_M) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, center_m=tuple(center_m), half_range_m=half_range_m)
        gym.ObservationWrapper.__init__(self, env)
        if not (np.isfinite(half_range_m) and half_range_m > 0):
            raise ValueError(f"half_range_m must be finite and > 0, got {half_range_m}")
        self.center_m = np.asarray(center_m, dtype=np.float64)
        self.half_range_m = float(half_range_m)
        scaled = {}
        if not isinstance(env.observation_space, spaces.Dict):
            raise TypeError(f"GoalScaling wraps a Dict observation space, got {env.observation_space}")
        for key, box in env.observation_space.spaces.items():
            if key in ("achieved_goal", "desired_goal") and isinstance(box, spaces.Box):
                box = spaces.Box(self._scale(box.low), self._scale(box.high), dtype=np.float32)
            scaled[key] = box
        self.observation_space = spaces.Dict(scaled)

    def _scale(self, goal_m: np.ndarray) -> np.ndarray:
        return scale_goal(goal_m, self.center_m, self.half_range_m)

    def unscale(self, goal: np.ndarray) -> np.ndarray:
        """Scaled goals (..., 3) back to camera-frame metres."""
        return np.asarray(goal, dtype=np.float64) * self.half_range_m + self.center_m

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {
            **observation,
            "achieved_goal": self._scale(observation["achieved_goal"]),
            "desired_goal": self._scale(observation["desired_goal"]),
        }

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Step; the reward is :meth:`compute_reward` of the scaled goals returned.

        It equals the env's reward up to float32 rounding of the goals (up to about 2e-5 mm),
        and exactly what HER recomputes for the same goals, as stable-baselines3 checks.
        """
        observation, _, terminated, truncated, info = self.env.step(action)
        observation = self.observation(observation)
        reward = float(self.compute_reward(observation["achieved_goal"], observation["desired_goal"], info))
        return observation, reward, terminated, truncated, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """The env's reward for scaled goals (..., 3), vectorised (HER calls this)."""
        goal_env: Any = self.env.unwrapped  # GridTouch-v0, whose compute_reward HER calls
        return goal_env.compute_reward(self.unscale(achieved_goal), self.unscale(desired_goal), info)


class TrainingYaws(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Choose the yaw of each training episode (reset options given by the caller win).

    Args:
        env: GridTouch-v0 (possibly wrapped).
        mode: "paper": a whole tour of the 35 circles at each of the paper's five yaws in
            turn (as in Phase II); "random": a uniform random yaw per circle from the env's
            seeded generator (the benchmark's sixth setting).
    """

    carried_attributes = ("_episodes",)
    """What one episode leaves to the next reset (see :meth:`dvrk_gym.envs.base.DvrkEnv.carried_state`)."""

    def __init__(self, env: gym.Env, mode: str = "paper") -> None:
        if mode not in TRAINING_YAWS:
            raise ValueError(f"training yaw mode must be one of {TRAINING_YAWS}, got {mode!r}")
        gym.utils.RecordConstructorArgs.__init__(self, mode=mode)
        gym.Wrapper.__init__(self, env)
        self.mode = mode
        self._episodes = 0

    def _check_carried_attributes(self, attributes: dict[str, Any]) -> None:
        """Refuse an episode count this wrapper could not have carried (see :class:`~dvrk_gym.envs.base.DvrkEnv`)."""
        check_int("carried '_episodes'", attributes["_episodes"], 0)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        episodes = 0 if seed is not None else self._episodes
        options = dict(options or {})
        if self.mode == "random":
            options.setdefault("yaw", "random")
        else:
            tour = episodes // N_CIRCLES
            options.setdefault("yaw", float(PAPER_YAWS_RAD[tour % len(PAPER_YAWS_RAD)]))
        result = self.env.reset(seed=seed, options=options)
        self._episodes = episodes + 1  # after the env took the reset: a refused one leaves the schedule as it was
        return result

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        return self.env.step(action)


class TourStart(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Begin GridTouch-v0's tour at its ``start``-th circle after each seeded reset (reset
    options given by the caller win), where it would begin at the first.

    A seeded reset starts the authors' tour (:data:`~dvrk_gym.envs.grid_touch.TOUR`) at its
    first circle whatever the seed, so sub-envs of one vector env, seeded ``seed + i``, would
    touch the same circle at every step; the training vector env gives sub-env i of n the
    start ``i * 35 // n`` instead.

    Args:
        env: GridTouch-v0 (possibly wrapped).
        start: the place in the tour, 0 to 34 (0: as without the wrapper).
    """

    def __init__(self, env: gym.Env, start: int) -> None:
        start = check_int("start", start, 0, N_CIRCLES - 1)
        gym.utils.RecordConstructorArgs.__init__(self, start=start)
        gym.Wrapper.__init__(self, env)
        self.start = start

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if seed is not None and self.start:
            options = {"circle": TOUR[self.start], **(options or {})}
        return self.env.reset(seed=seed, options=options)


def wrap_grid_touch(env: gym.Env, training_yaws: str | None = None) -> gym.Env:
    """GridTouch-v0 as the agents see it: scaled goals, ``(bx, by, bz)`` actions in [-1, 1].

    Args:
        env: a GridTouch-v0 env.
        training_yaws: None for evaluation (the caller's reset options choose the yaw), or
            a :data:`TRAINING_YAWS` mode.
    """
    if training_yaws is not None:
        env = TrainingYaws(env, training_yaws)
    env = TargetYawAction(env)
    # Plain ints, not arrays: the wrapped env's spec stays JSON (a Python float would draw
    # Box's float64-to-float32 warning; the float32 bounds are the same either way).
    env = RescaleAction(env, min_action=cast(Any, -1), max_action=cast(Any, 1))
    return GoalScaling(env)  # outermost, so that ``env.compute_reward`` is found (SB3's check_env)
