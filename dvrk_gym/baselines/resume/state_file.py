"""A training run's whole state in one file, written without pickles, so a killed run resumes bit for bit.

:func:`save_training_state` writes a zip (atomically: the old file or the new one, never
half of one) holding

- ``state.json``: the format tag, the source fingerprint of the dvrk_gym that wrote it, the
  training settings, the counters (env steps, gradient updates, episodes), the replay
  buffer's position, the global random generators (numpy's, Python's) and the action
  space's, each training env's last reset (:mod:`~dvrk_gym.baselines.resume.reset_records`), and
  the training loop's own record (``progress``: the learning curve so far, say);
- ``tensors.safetensors``: the policy's weights, the optimisers' state (Adam's moments and
  step counts), SAC's entropy coefficient and torch's random generator;
- ``arrays/<name>.npy``: the filled rows of the replay buffer (HER's episode bookkeeping
  too) and the observation the agent acts on next.

:func:`~dvrk_gym.baselines.resume.restore.restore_training_state` puts all of it back into a freshly built model of the same
settings. Every size is bounded before anything is read or allocated (the zip's declared
sizes against what the model's own buffer and networks can hold), every array and tensor
must have the shape and dtype the model has, and the envs' replayed resets must give back
the saved observation bit for bit. A file written by another version of dvrk_gym is refused:
its run could not be continued as the same run.
"""

from __future__ import annotations

import functools
import importlib.metadata
import json
import random
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import safetensors.torch
import torch
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.her import HerReplayBuffer

from dvrk_gym.utils.atomic import atomic_path
from dvrk_gym.utils.source_fingerprint import source_fingerprint

FORMAT = "dvrk_gym.training_state/1"
"""Tag of ``state.json``, checked on load."""
STATE_JSON = "state.json"
TENSORS = "tensors.safetensors"
ARRAYS = "arrays/"
MAX_JSON_BYTES = 16 * 2**20
"""The largest ``state.json`` read, bytes (a few hundred kilobytes in practice)."""
NPY_HEADER_BYTES = 4096
"""Room allowed for an ``.npy`` member's header, bytes."""
TENSOR_SLACK_BYTES = 2**20
"""Room allowed for the safetensors header and small tensors (steps, entropy, generator), bytes."""
LIBRARIES = ("numpy", "scipy", "numba", "opencv-python-headless", "torch", "stable_baselines3", "gymnasium", "pybullet")
"""Libraries whose versions a resume must share with the run it continues: each moves the
last bits of a training (kernels, samplers, the physics), so another version would not
continue the same run."""


class TrainingStateError(ValueError):
    """A training-state file that cannot be resumed here (the message names the file and why)."""


# ---------------------------------------------------------------------- what is saved
def model_optimizers(model: OffPolicyAlgorithm) -> dict[str, torch.optim.Optimizer]:
    found = {name: getattr(model, name).optimizer for name in ("actor", "critic") if hasattr(getattr(model, name, None), "optimizer")}
    entropy = getattr(model, "ent_coef_optimizer", None)
    if entropy is not None:
        found["ent_coef"] = entropy
    return found


def saved_tensors(model: OffPolicyAlgorithm) -> dict[str, torch.Tensor]:
    tensors = {f"policy/{key}": value for key, value in model.policy.state_dict().items()}
    for name, optimizer in model_optimizers(model).items():
        for index, values in optimizer.state_dict()["state"].items():
            for key, value in values.items():
                tensors[f"optimizer/{name}/{index}/{key}"] = torch.as_tensor(value)
    log_ent_coef = getattr(model, "log_ent_coef", None)
    if isinstance(log_ent_coef, torch.Tensor):
        tensors["log_ent_coef"] = log_ent_coef
    tensors["rng/torch"] = torch.get_rng_state()
    return {key: value.detach().cpu().clone().contiguous() for key, value in tensors.items()}


def buffer_arrays(model: OffPolicyAlgorithm) -> dict[str, np.ndarray]:
    """The replay buffer's arrays, whole (row = one vector-env step)."""
    buffer = model.replay_buffer
    if buffer is None:
        raise ValueError("the model has no replay buffer")
    arrays: dict[str, np.ndarray] = {}
    if isinstance(buffer, DictReplayBuffer):
        arrays.update({f"observations.{key}": value for key, value in buffer.observations.items()})
        arrays.update({f"next_observations.{key}": value for key, value in buffer.next_observations.items()})
    else:
        arrays.update({"observations": buffer.observations, "next_observations": buffer.next_observations})
    arrays.update({"actions": buffer.actions, "rewards": buffer.rewards, "dones": buffer.dones, "timeouts": buffer.timeouts})
    if isinstance(buffer, HerReplayBuffer):
        arrays.update({"ep_start": buffer.ep_start, "ep_length": buffer.ep_length})
    return arrays


def check_supported(model: Any) -> OffPolicyAlgorithm:
    if not isinstance(model, OffPolicyAlgorithm):
        raise ValueError(f"a training state is saved for off-policy agents (a replay buffer), not {type(model).__name__}")
    buffer = model.replay_buffer
    if getattr(buffer, "optimize_memory_usage", False):
        raise ValueError("a training state is not saved for a memory-optimised replay buffer")
    if isinstance(buffer, HerReplayBuffer) and buffer.copy_info_dict:
        raise ValueError("a training state does not save HER's info dicts (copy_info_dict=True)")
    return model


def training_envs(model: OffPolicyAlgorithm) -> VecEnv:
    env = model.get_env()
    if env is None:
        raise ValueError("the model has no training envs")
    return env


def filled_rows(buffer: Any) -> int:
    return int(buffer.buffer_size if buffer.full else buffer.pos)


def stack_observations(observations: list[Any]) -> dict[str, np.ndarray]:
    if isinstance(observations[0], dict):
        return {key: np.stack([np.asarray(o[key]) for o in observations]) for key in observations[0]}
    return {"": np.stack([np.asarray(o) for o in observations])}


def last_observation(model: OffPolicyAlgorithm) -> dict[str, np.ndarray]:
    last = model._last_obs
    return {key: np.asarray(value) for key, value in last.items()} if isinstance(last, dict) else {"": np.asarray(last)}


# ---------------------------------------------------------------------- save
def save_training_state(path: str | Path, model: Any, config: dict[str, Any], progress: dict[str, Any]) -> Path:
    """Write ``model``'s training state, at a moment when every training env has just been reset.

    Args:
        path: the file to write (a zip; replaced atomically).
        model: an off-policy stable-baselines3 model whose envs are wrapped in
            :class:`~dvrk_gym.baselines.resume.reset_records.ResetRecorder` (outermost).
        config: the training settings, JSON values: a resume must give the same.
        progress: the training loop's own record, JSON values, given back by :func:`restore_training_state`.

    Raises:
        ValueError: not an off-policy model; a memory-optimised replay buffer, or HER's with
            ``copy_info_dict=True`` (whose info dicts are not saved); envs not wrapped in
            ``ResetRecorder``; or an env in the middle of an episode.
    """
    model = check_supported(model)
    try:
        between = training_envs(model).env_method("between_episodes")
    except AttributeError:
        raise ValueError("a training state needs its training envs wrapped in ResetRecorder (outermost)") from None
    if not all(between):
        raise ValueError("a training state is saved between episodes: every training env must just have been reset")
    buffer = model.replay_buffer
    rows = filled_rows(buffer)
    numpy_state: Any = np.random.get_state(legacy=True)  # ('MT19937', keys, pos, has_gauss, cached_gaussian)
    state: dict[str, Any] = {
        "format": FORMAT,
        "source": source_fingerprint().to_json(),
        "libraries": library_versions(),
        "config": json.loads(json.dumps(config)),
        "num_timesteps": int(model.num_timesteps),
        "n_updates": int(model._n_updates),
        "episode_num": int(model._episode_num),
        "buffer": {"pos": int(buffer.pos), "full": bool(buffer.full)},
        "rng": {
            "numpy": [numpy_state[0], numpy_state[1].tolist(), int(numpy_state[2]), int(numpy_state[3]), float(numpy_state[4])],
            "python": [random.getstate()[0], list(random.getstate()[1]), random.getstate()[2]],
            "action_space": model.action_space.np_random.bit_generator.state,
        },
        "envs": training_envs(model).env_method("last_reset"),
        "progress": progress,
    }
    if isinstance(buffer, HerReplayBuffer):
        state["buffer"]["current_ep_start"] = [int(x) for x in buffer._current_ep_start]
    arrays = {name: value[:rows] for name, value in buffer_arrays(model).items()}
    arrays.update({f"last_obs.{key}": value for key, value in last_observation(model).items()})
    tensors = safetensors.torch.save(saved_tensors(model))
    with atomic_path(path) as temporary, zipfile.ZipFile(temporary, "w", compression=zipfile.ZIP_STORED) as archive:
        archive.writestr(STATE_JSON, json.dumps(state, allow_nan=False))
        archive.writestr(TENSORS, tensors)
        for name, value in arrays.items():
            with archive.open(f"{ARRAYS}{name}.npy", "w") as stream:
                np.lib.format.write_array(stream, np.ascontiguousarray(value), allow_pickle=False)
    return Path(path)


@functools.cache
def library_versions() -> dict[str, str | None]:
    """The installed versions of :data:`LIBRARIES` (None for one without metadata), read once
    per process (do not modify the result)."""
    versions: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions
