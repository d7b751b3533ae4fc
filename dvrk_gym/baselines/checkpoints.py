"""Save a trained agent as stable-baselines3's zip plus a JSON of its settings; load its weights.

:func:`save_agent` writes ``<name>.zip`` with SB3's ``save`` (usable by ``SAC.load`` and
friends) and ``<name>.json`` beside it: the training config, the policy's network
settings, the goal scaling and the env steps trained. :func:`load_agent` does not use
SB3's ``load``, which unpickles (cloudpickle) part of the zip and so can run code from a
crafted file: it rebuilds the model from the JSON and reads only the policy's weights
(``policy.pth`` inside the zip) with ``torch.load(..., weights_only=True)``. Even so, only
load files this tool wrote, or that you trust.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from stable_baselines3.common.base_class import BaseAlgorithm

from dvrk_gym.baselines.agents import ALGORITHMS
from dvrk_gym.baselines.training import TrainConfig, TrainResult, make_agent_env
from dvrk_gym.baselines.wrappers import GOAL_CENTER_M, GOAL_HALF_RANGE_M

FORMAT = "dvrk_gym.baselines/1"
"""Tag of the settings JSON, checked on load."""
POLICY_WEIGHTS = "policy.pth"
"""The member of SB3's zip that holds the policy's state dict."""


@dataclass(frozen=True)
class LoadedAgent:
    """An agent read back by :func:`load_agent`.

    Attributes:
        model: the model, with the trained policy weights (no replay buffer, no optimiser state).
        config: its training settings (the env to evaluate it on follows from them).
        env_steps: env steps (robot moves) it was trained with.
        path: the zip it came from.
    """

    model: BaseAlgorithm
    config: TrainConfig
    env_steps: int
    path: Path

    @property
    def label(self) -> str:
        """A short name for tables: the agent, its budget and seed."""
        return f"{self.config.agent} ({self.env_steps} steps, seed {self.config.seed})"


def settings_path(model_path: Path) -> Path:
    """The settings JSON beside a model zip."""
    return Path(model_path).with_suffix(".json")


def save_agent(result: TrainResult, path: Path) -> Path:
    """Write ``result.model`` to ``path`` (a .zip) and its settings to the .json beside it.

    Returns:
        The zip's path.
    """
    path = Path(path).with_suffix(".zip")
    path.parent.mkdir(parents=True, exist_ok=True)
    result.model.save(path)
    settings = {
        "format": FORMAT,
        "config": result.config.to_dict(),
        "policy_kwargs": _policy_kwargs(result.model),
        "goal_scaling": {"center_m": list(GOAL_CENTER_M), "half_range_m": GOAL_HALF_RANGE_M},
        "env_steps": result.env_steps,
        "train_seconds": result.train_seconds,
        "steps_per_second": result.steps_per_second,
    }
    settings_path(path).write_text(json.dumps(settings, indent=1))
    return path


def _policy_kwargs(model: BaseAlgorithm) -> dict[str, Any]:
    kwargs = dict(model.policy_kwargs)
    try:
        json.dumps(kwargs)
    except TypeError as error:
        raise ValueError(f"policy_kwargs must be plain JSON values to be saved safely, got {kwargs!r}: {error}") from None
    return kwargs


def _read_settings(path: Path) -> dict[str, Any]:
    json_path = settings_path(path)
    if not Path(path).exists():
        raise FileNotFoundError(f"no model file {path}")
    if not json_path.exists():
        raise FileNotFoundError(f"{json_path} is missing: models are saved by 'dvrk-gym baseline train' as a .zip and a .json side by side")
    settings = json.loads(json_path.read_text())
    if settings.get("format") != FORMAT:
        raise ValueError(f"{json_path} is not a dvrk_gym baseline settings file (format {settings.get('format')!r}, expected {FORMAT!r})")
    scaling = settings["goal_scaling"]
    if tuple(scaling["center_m"]) != tuple(GOAL_CENTER_M) or scaling["half_range_m"] != GOAL_HALF_RANGE_M:
        raise ValueError(f"{path} was trained with goal scaling {scaling}, but this version scales by {GOAL_CENTER_M}, {GOAL_HALF_RANGE_M}")
    return settings


def _policy_weights(path: Path) -> dict[str, torch.Tensor]:
    with zipfile.ZipFile(path) as archive:
        if POLICY_WEIGHTS not in archive.namelist():
            raise ValueError(f"{path} holds no {POLICY_WEIGHTS}; is it a stable-baselines3 zip?")
        buffer = io.BytesIO(archive.read(POLICY_WEIGHTS))
    return torch.load(buffer, map_location="cpu", weights_only=True)


def load_agent(path: Path) -> LoadedAgent:
    """Rebuild an agent saved by :func:`save_agent`, reading only tensors from the zip.

    Raises:
        FileNotFoundError: the zip or its settings JSON is missing.
        ValueError: the files are not an agent of this tool, or do not match this version.
    """
    path = Path(path)
    settings = _read_settings(path)
    config = TrainConfig(**settings["config"])
    env = make_agent_env(config, training=False)
    try:
        algorithm = ALGORITHMS[config.spec.algorithm]
        model = algorithm("MultiInputPolicy", env, policy_kwargs=settings["policy_kwargs"], device="cpu", **_inference_only(algorithm))
        model.policy.load_state_dict(_policy_weights(path))
    except RuntimeError as error:
        raise ValueError(f"the weights in {path} do not fit the network its settings describe: {error}") from None
    finally:
        env.close()
    model.policy.set_training_mode(False)
    return LoadedAgent(model, config, int(settings["env_steps"]), path)


def _inference_only(algorithm: type[BaseAlgorithm]) -> dict[str, Any]:
    """Constructor keywords that keep an inference-only model small (a one-row buffer)."""
    if "buffer_size" in algorithm.__init__.__code__.co_varnames:
        return {"buffer_size": 1}
    return {}
