"""Debridement-v0 (primitive mode, one pick per step) as the pick agents see it.

The agent learns what a calibrator provides: where to send the robot so that the jaws
land on the fragment the endoscope sees. What it sees (:func:`pick_observation`) is the
pick target the calibrated policy uses, :func:`~dvrk_gym.envs.debridement.fragment_target`
(the camera-frame centre of the first fragment seen, scaled like GridTouch's goals by
:func:`~dvrk_gym.baselines.wrappers.scale_goal`) and the tool yaw of the image rule,
rounded to the nearest of the paper's five yaws as :class:`CalibratedPolicy` rounds it,
divided by pi/2. Its action is ``(bx, by, bz)`` in [-1, 1], mapped linearly onto the
pick's base-frame box (metres); the yaw comes from the image rule (:func:`pick_action`).

The reward (:class:`ShapedPickReward`) is the env's 1 per delivered fragment minus the
true grip offset, the simulator's truth, as GridTouch's dense reward uses the true touch
distance: ``delivered - (offset_mm + above_mm) / OFFSET_SCALE_MM``, where ``offset_mm`` is
the distance in the paper's plane from the fragment's centre to the closed jaw tip when
the jaws start to close and ``above_mm`` how far that tip was above the fragment's top
(0 when below it, as it should be), each capped at MAX_PENALTY_MM.
"""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from dvrk_gym.baselines.wrappers import scale_goal
from dvrk_gym.envs.debridement import PICK_HIGH, PICK_LOW, fragment_target
from dvrk_gym.sim.robot import kinematics as kin

OFFSET_SCALE_MM = 2.0
"""Millimetres of grip offset that cost as much as a delivered fragment earns."""
MAX_PENALTY_MM = 30.0
"""Cap of each penalty term, millimetres (and the offset charged when no grip was recorded)."""
OBSERVATION_NAMES = ("target_x", "target_y", "target_z", "yaw")


def pick_yaw(observation: dict[str, np.ndarray]) -> float:
    """The tool yaw of the image rule for the pick target, rounded to the nearest paper yaw, rad."""
    _, angle = fragment_target(observation)
    return float(kin.nearest_paper_yaw(angle))


def pick_observation(observation: dict[str, np.ndarray]) -> np.ndarray:
    """The pick agent's (4,) observation: the scaled camera-frame target and yaw / (pi/2)."""
    position, _ = fragment_target(observation)
    return np.append(scale_goal(position), np.float32(pick_yaw(observation) / (math.pi / 2))).astype(np.float32)


def unit_to_pick_box(action: np.ndarray) -> np.ndarray:
    """(bx, by, bz) in [-1, 1] to the pick's base-frame box, metres (clipped to the box)."""
    unit = np.clip(np.asarray(action, dtype=np.float64).reshape(3), -1.0, 1.0)
    return PICK_LOW[:3] + (unit + 1.0) / 2.0 * (PICK_HIGH[:3] - PICK_LOW[:3])


def pick_action(action: np.ndarray, yaw_rad: float) -> np.ndarray:
    """The env's action ``(bx, by, bz, yaw)`` (metres, rad) from a unit action and a yaw."""
    return np.append(unit_to_pick_box(action), yaw_rad).astype(np.float32)


class PickTargetAgentView(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Debridement-v0 in primitive mode seen through :func:`pick_observation` and :func:`pick_action`.

    Observation: a Dict with one key, ``"observation"`` (4,): the scaled target (x, y, z)
    and the yaw / (pi/2). Action: ``(bx, by, bz)`` in [-1, 1].
    """

    def __init__(self, env: gym.Env) -> None:
        if getattr(env.unwrapped, "primitive", None) is not True:
            raise ValueError("the pick agents need Debridement-v0 in primitive mode (action_mode='primitive')")
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self.observation_space = spaces.Dict({"observation": spaces.Box(-10.0, 10.0, shape=(len(OBSERVATION_NAMES),), dtype=np.float32)})
        self._yaw = 0.0

    def _view(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self._yaw = pick_yaw(observation)
        return {"observation": pick_observation(observation)}

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        return self._view(observation), info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(pick_action(action, self._yaw))
        return self._view(observation), reward, terminated, truncated, info


def shaped_pick_reward(delivered: float, info: dict[str, Any]) -> float:
    """``delivered - (offset_mm + above_mm) / OFFSET_SCALE_MM`` from a pick's info (see the module)."""
    offset_m = info.get("true_grip_offset_m")
    if offset_m is None:  # no grip recorded (nothing on the paper, or the physics failed)
        offset_mm, above_mm = MAX_PENALTY_MM, 0.0
    else:
        offset_mm = min(1e3 * float(np.linalg.norm(offset_m)), MAX_PENALTY_MM)
        above_mm = min(max(1e3 * float(info.get("true_tip_above_fragment_m", 0.0)), 0.0), MAX_PENALTY_MM)
    return float(delivered) - (offset_mm + above_mm) / OFFSET_SCALE_MM


class ShapedPickReward(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace the env's reward of a pick by :func:`shaped_pick_reward` (the env's kept in ``info["delivered"]``)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        info = {**info, "delivered": float(reward)}
        return observation, shaped_pick_reward(float(reward), info), terminated, truncated, info


def wrap_debridement(env: gym.Env, training_yaws: str | None = None) -> gym.Env:
    """Debridement-v0 (primitive mode) as the pick agents see it, with the shaped reward.

    Args:
        env: a Debridement-v0 env in primitive mode.
        training_yaws: ignored (the yaw of a pick comes from the fragment); accepted so
            that every agent's wrapper has the same signature.
    """
    return PickTargetAgentView(ShapedPickReward(env))


class GripOffsetLog(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Record each pick's true grip offset in the paper's plane, mm (None when no grip was recorded)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self.offsets_mm: list[float | None] = []

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        offset_m = info.get("true_grip_offset_m")
        self.offsets_mm.append(None if offset_m is None else 1e3 * float(np.linalg.norm(offset_m)))
        return observation, reward, terminated, truncated, info
