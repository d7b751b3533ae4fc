"""The base every dvrk_gym environment is built on: one world, one config, strict inputs.

A subclass names its config dataclass (``config_class``), its action components
(``action_names``) and implements ``_reset_episode`` and ``_step_episode``. The base owns
the world, the argument and action checks, seeding, state restoration and rendering, so
no environment repeats them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded

from dvrk_gym.sim.robot.bias import BiasConfig
from dvrk_gym.sim.world import DvrkWorld, WorldConfig


@dataclass(frozen=True)
class EnvConfig:
    """Settings every environment shares.

    Attributes:
        bias: cable bias, a preset name ("none", "paper", "severe") or a BiasConfig.
        bias_seed: which instrument to draw from the bias distribution (fixed for the
            life of the env; episodes are seeded separately through ``reset(seed=...)``).
        camera_resolution: (width, height) of each endoscope image, pixels.
        pixel_noise_px: standard deviation of the detection noise added to every pixel
            coordinate the cameras report, at 1920 x 1080 (scaled with the resolution).
    """

    bias: str | BiasConfig = "paper"
    bias_seed: int = 0
    camera_resolution: tuple[int, int] = (1920, 1080)
    pixel_noise_px: float = 0.0

    def __post_init__(self) -> None:
        # gym.make passes lists from JSON-like specs; the world wants a tuple.
        object.__setattr__(self, "camera_resolution", tuple(self.camera_resolution))


def make_config(config_class: type[EnvConfig], kwargs: dict[str, Any]) -> EnvConfig:
    """Build ``config_class`` from keyword arguments, refusing unknown names clearly."""
    valid = {f.name for f in dataclasses.fields(config_class)}
    unknown = sorted(set(kwargs) - valid)
    if unknown:
        raise ValueError(f"unknown argument(s) {unknown} for {config_class.__name__}; valid: {sorted(valid)}")
    return config_class(**kwargs)


def check_action(action: Any, space: gym.spaces.Box, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Validate an action against a Box space.

    Returns:
        (the action clipped into the space as float64, boolean mask of clipped elements).

    Raises:
        ValueError: wrong shape, or an element that is NaN or infinite (named in the message).
    """
    array = np.asarray(action, dtype=np.float64)
    if array.shape != space.shape:
        raise ValueError(f"action must have shape {space.shape} ({', '.join(names)}), got {array.shape}")
    for i, value in enumerate(array):
        if not np.isfinite(value):
            raise ValueError(
                f"action[{i}] ({names[i]}) is {value}; expected a finite value in "
                f"[{space.low[i]:.4g}, {space.high[i]:.4g}]"
            )
    clipped = np.clip(array, space.low.astype(np.float64), space.high.astype(np.float64))
    return clipped, clipped != array


class DvrkEnv(gym.Env):
    """Shared machinery of the dvrk_gym environments.

    Args:
        render_mode: None (default), "rgb_array" (the left endoscope image) or "human"
            (the PyBullet GUI; needs a display).
        **kwargs: fields of the environment's config dataclass.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 4}
    config_class: ClassVar[type[EnvConfig]] = EnvConfig
    action_names: ClassVar[tuple[str, ...]] = ()
    option_names: ClassVar[tuple[str, ...]] = ()

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.config = make_config(self.config_class, kwargs)
        self.world = DvrkWorld(
            WorldConfig(
                camera_resolution=self.config.camera_resolution,
                bias=self.config.bias,
                bias_seed=self.config.bias_seed,
                gui=render_mode == "human",
                pixel_noise_px=self.config.pixel_noise_px,
            )
        )
        self._initial_physics_state = self.world.physics.client.saveState()
        self._needs_reset = True

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(self.option_names))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; valid options: {list(self.option_names)}")
        self._restore_initial_state()
        observation, info = self._reset_episode(options)
        self._needs_reset = False
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise ResetNeeded("call reset() before step(): the episode has not started or has ended")
        clipped, clamped = check_action(action, self.action_space, self.action_names)
        observation, reward, terminated, truncated, info = self._step_episode(clipped, clamped)
        if terminated or truncated:
            self._needs_reset = True
        return observation, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self.world.render("left")
        return None  # "human": the PyBullet GUI shows the world live; None: nothing to draw

    def close(self) -> None:
        if hasattr(self, "world"):
            self.world.close()
        super().close()

    # ------------------------------------------------------------------ helpers for subclasses
    def _restore_initial_state(self) -> None:
        """Put the physics back as it was when the env was made (an env that rebuilds its
        world on reset overrides this)."""
        self.world.physics.client.restoreState(self._initial_physics_state)

    def _reset_episode(self, options: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
        raise NotImplementedError

    def _step_episode(self, action: np.ndarray, clamped: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        raise NotImplementedError

    def _clamped_names(self, clamped: np.ndarray, joints_clamped: np.ndarray | None = None) -> list[str]:
        """Names of the clamped action elements and joints, for ``info["clamped"]``."""
        names = [self.action_names[i] for i in np.flatnonzero(clamped)]
        if joints_clamped is not None:
            from dvrk_gym.sim.robot.kinematics import JOINT_NAMES

            names += [f"joint:{JOINT_NAMES[i]}" for i in np.flatnonzero(joints_clamped)]
        return names
