"""A training run's whole state in one file, written without pickles, so a killed run resumes bit for bit.

:func:`save_training_state` writes a zip (atomically: the old file or the new one, never
half of one) holding

- ``state.json``: the format tag, the source fingerprint of the dvrk_gym that wrote it, the
  training settings, the counters (env steps, gradient updates, episodes), the replay
  buffer's position, the global random generators (numpy's, Python's) and the action
  space's, each training env's last reset (:mod:`~dvrk_gym.baselines.resume.snapshots`), and
  the training loop's own record (``progress``: the learning curve so far, say);
- ``tensors.safetensors``: the policy's weights, the optimisers' state (Adam's moments and
  step counts), SAC's entropy coefficient and torch's random generator;
- ``arrays/<name>.npy``: the filled rows of the replay buffer (HER's episode bookkeeping
  too) and the observation the agent acts on next.

:func:`restore_training_state` puts all of it back into a freshly built model of the same
settings. Every size is bounded before anything is read or allocated (the zip's declared
sizes against what the model's own buffer and networks can hold), every array and tensor
must have the shape and dtype the model has, and the envs' replayed resets must give back
the saved observation bit for bit. A file written by another version of dvrk_gym is refused:
its run could not be continued as the same run.
"""

from __future__ import annotations

import io
import json
import random
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import safetensors.torch
import torch
from safetensors import SafetensorError
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.her import HerReplayBuffer

from dvrk_gym.utils.atomic import atomic_path
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, open_archive, read_member
from dvrk_gym.utils.source_fingerprint import SourceFingerprint, source_fingerprint

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


class TrainingStateError(ValueError):
    """A training-state file that cannot be resumed here (the message names the file and why)."""


# ---------------------------------------------------------------------- what is saved
def _optimizers(model: OffPolicyAlgorithm) -> dict[str, torch.optim.Optimizer]:
    found = {name: getattr(model, name).optimizer for name in ("actor", "critic") if hasattr(getattr(model, name, None), "optimizer")}
    entropy = getattr(model, "ent_coef_optimizer", None)
    if entropy is not None:
        found["ent_coef"] = entropy
    return found


def _tensors(model: OffPolicyAlgorithm) -> dict[str, torch.Tensor]:
    tensors = {f"policy/{key}": value for key, value in model.policy.state_dict().items()}
    for name, optimizer in _optimizers(model).items():
        for index, values in optimizer.state_dict()["state"].items():
            for key, value in values.items():
                tensors[f"optimizer/{name}/{index}/{key}"] = torch.as_tensor(value)
    log_ent_coef = getattr(model, "log_ent_coef", None)
    if isinstance(log_ent_coef, torch.Tensor):
        tensors["log_ent_coef"] = log_ent_coef
    tensors["rng/torch"] = torch.get_rng_state()
    return {key: value.detach().cpu().clone().contiguous() for key, value in tensors.items()}


def _buffer_arrays(model: OffPolicyAlgorithm) -> dict[str, np.ndarray]:
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


def _check_supported(model: Any) -> OffPolicyAlgorithm:
    if not isinstance(model, OffPolicyAlgorithm):
        raise ValueError(f"a training state is saved for off-policy agents (a replay buffer), not {type(model).__name__}")
    buffer = model.replay_buffer
    if getattr(buffer, "optimize_memory_usage", False):
        raise ValueError("a training state is not saved for a memory-optimised replay buffer")
    if isinstance(buffer, HerReplayBuffer) and buffer.copy_info_dict:
        raise ValueError("a training state does not save HER's info dicts (copy_info_dict=True)")
    return model


def _vec_env(model: OffPolicyAlgorithm) -> VecEnv:
    env = model.get_env()
    if env is None:
        raise ValueError("the model has no training envs")
    return env


def _filled_rows(buffer: Any) -> int:
    return int(buffer.buffer_size if buffer.full else buffer.pos)


def _stack_observations(observations: list[Any]) -> dict[str, np.ndarray]:
    if isinstance(observations[0], dict):
        return {key: np.stack([np.asarray(o[key]) for o in observations]) for key in observations[0]}
    return {"": np.stack([np.asarray(o) for o in observations])}


def _last_observation(model: OffPolicyAlgorithm) -> dict[str, np.ndarray]:
    last = model._last_obs
    return {key: np.asarray(value) for key, value in last.items()} if isinstance(last, dict) else {"": np.asarray(last)}


# ---------------------------------------------------------------------- save
def save_training_state(path: str | Path, model: Any, config: dict[str, Any], progress: dict[str, Any]) -> Path:
    """Write ``model``'s training state, at a moment when every training env has just been reset.

    Args:
        path: the file to write (a zip; replaced atomically).
        model: an off-policy stable-baselines3 model whose envs are wrapped in
            :class:`~dvrk_gym.baselines.resume.snapshots.ResetRecorder` (outermost).
        config: the training settings, JSON values: a resume must give the same.
        progress: the training loop's own record, JSON values, given back by :func:`restore_training_state`.

    Raises:
        ValueError: not an off-policy model, or an env is in the middle of an episode.
    """
    model = _check_supported(model)
    if not all(_vec_env(model).env_method("between_episodes")):
        raise ValueError("a training state is saved between episodes: every training env must just have been reset")
    buffer = model.replay_buffer
    rows = _filled_rows(buffer)
    numpy_state: Any = np.random.get_state(legacy=True)  # ('MT19937', keys, pos, has_gauss, cached_gaussian)
    state: dict[str, Any] = {
        "format": FORMAT,
        "source": source_fingerprint().to_json(),
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
        "envs": _vec_env(model).env_method("last_reset"),
        "progress": progress,
    }
    if isinstance(buffer, HerReplayBuffer):
        state["buffer"]["current_ep_start"] = [int(x) for x in buffer._current_ep_start]
    arrays = {name: value[:rows] for name, value in _buffer_arrays(model).items()}
    arrays.update({f"last_obs.{key}": value for key, value in _last_observation(model).items()})
    tensors = safetensors.torch.save(_tensors(model))
    with atomic_path(path) as temporary, zipfile.ZipFile(temporary, "w", compression=zipfile.ZIP_STORED) as archive:
        archive.writestr(STATE_JSON, json.dumps(state, allow_nan=False))
        archive.writestr(TENSORS, tensors)
        for name, value in arrays.items():
            with archive.open(f"{ARRAYS}{name}.npy", "w") as stream:
                np.lib.format.write_array(stream, np.ascontiguousarray(value), allow_pickle=False)
    return Path(path)


# ---------------------------------------------------------------------- restore
def restore_training_state(path: str | Path, model: Any, config: dict[str, Any]) -> dict[str, Any]:
    """Put the training state saved at ``path`` back into ``model``; its ``progress`` record.

    ``model`` must be freshly built with the same settings (``config``) on training envs
    wrapped as :func:`save_training_state` wants, and not yet trained. After this, continue
    with ``model.learn(remaining, reset_num_timesteps=False)``.

    Raises:
        FileNotFoundError: no such file.
        TrainingStateError: the file is not a training state of these settings written by
            this version of dvrk_gym, or is corrupt or tampered with (the message says which).
    """
    model = _check_supported(model)
    path = Path(path)
    buffer = model.replay_buffer
    arrays = _buffer_arrays(model)
    tensor_bytes = 3 * sum(t.numel() * t.element_size() for t in model.policy.state_dict().values()) + TENSOR_SLACK_BYTES
    last_bytes = sum(value.nbytes for value in _last_observation_template(model).values())
    largest = max([value.nbytes for value in arrays.values()] + [tensor_bytes, MAX_JSON_BYTES])
    total = sum(value.nbytes for value in arrays.values()) + tensor_bytes + MAX_JSON_BYTES + last_bytes
    limits = ArchiveLimits(
        max_file_bytes=total + (len(arrays) + 8) * NPY_HEADER_BYTES,
        max_members=len(arrays) + 32,
        max_member_bytes=largest + NPY_HEADER_BYTES,
        max_total_bytes=total + (len(arrays) + 8) * NPY_HEADER_BYTES,
    )
    try:
        with open_archive(path, limits) as archive:
            state = _read_state_json(archive, config)
            rows = _check_buffer_position(state["buffer"], buffer)
            tensors = _read_tensors(archive, tensor_bytes)
            saved = {
                name: _read_array(archive, f"{ARRAYS}{name}.npy", (rows, *value.shape[1:]), value.dtype) for name, value in arrays.items()
            }
            last = {
                key: _read_array(archive, f"{ARRAYS}last_obs.{key}.npy", value.shape, value.dtype)
                for key, value in _last_observation_template(model).items()
            }
        _restore_tensors(model, tensors)
        for name, value in arrays.items():
            value[:rows] = saved[name]
        buffer.pos, buffer.full = state["buffer"]["pos"], state["buffer"]["full"]
        if isinstance(buffer, HerReplayBuffer):
            buffer._current_ep_start = _int_array(
                state["buffer"].get("current_ep_start"), buffer._current_ep_start.shape, "current_ep_start"
            )
        model.num_timesteps = _count(state, "num_timesteps")
        model._n_updates = _count(state, "n_updates")
        model._episode_num = _count(state, "episode_num")
        _replay_envs(model, state["envs"], last)
        _restore_generators(model, state["rng"])
    except (ArchiveLimitError, SafetensorError, KeyError, TypeError, ValueError, RuntimeError, IndexError) as error:
        if isinstance(error, TrainingStateError):
            raise
        raise TrainingStateError(f"{path}: not a training state these settings can resume ({type(error).__name__}: {error})") from None
    progress = state["progress"]
    if not isinstance(progress, dict):
        raise TrainingStateError(f"{path}: its 'progress' record is not a dict")
    return progress


def _last_observation_template(model: OffPolicyAlgorithm) -> dict[str, np.ndarray]:
    """Zero arrays shaped as the batch of observations the agent acts on (one per training env)."""
    space: Any = model.observation_space
    n_envs = _vec_env(model).num_envs
    if isinstance(getattr(space, "spaces", None), dict):
        return {key: np.zeros((n_envs, *sub.shape), dtype=sub.dtype) for key, sub in space.spaces.items()}
    return {"": np.zeros((n_envs, *space.shape), dtype=space.dtype)}


def _read_state_json(archive: zipfile.ZipFile, config: dict[str, Any]) -> dict[str, Any]:
    state = json.loads(read_member(archive, STATE_JSON, ArchiveLimits(max_member_bytes=MAX_JSON_BYTES)))
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise TrainingStateError(f"{archive.filename}: not a dvrk_gym training state (format {found!r}, expected {FORMAT!r})")
    here, there = source_fingerprint(), SourceFingerprint.from_json(state.get("source"))
    if there is None or there.sha256 != here.sha256:
        made_by = there.short() if there is not None else "an unknown version"
        raise TrainingStateError(
            f"{archive.filename}: written by {made_by}; this is {here.short()}. A run resumed by other code would not be the run it "
            "continues: resume it with the version that wrote it, or delete the file to train afresh"
        )
    wanted = json.loads(json.dumps(config))
    if state.get("config") != wanted:
        recorded: dict[str, Any] = state["config"] if isinstance(state.get("config"), dict) else {}
        differ = sorted(key for key in set(wanted) | set(recorded) if wanted.get(key) != recorded.get(key))
        raise TrainingStateError(
            f"{archive.filename}: a training state of other settings (differing in {', '.join(differ)}); "
            "give another output folder, or delete the file to train afresh"
        )
    for key in ("buffer", "rng", "envs", "progress"):
        if key not in state:
            raise TrainingStateError(f"{archive.filename}: its state.json has no {key!r}")
    return state


def _count(state: dict[str, Any], key: str) -> int:
    value = state.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 10**12:
        raise ValueError(f"{key!r} must be an int in [0, 1e12], got {value!r}")
    return value


def _check_buffer_position(position: Any, buffer: Any) -> int:
    if not isinstance(position, dict):
        raise ValueError("'buffer' must be a dict")
    pos, full = position.get("pos"), position.get("full")
    if isinstance(pos, bool) or not isinstance(pos, int) or not 0 <= pos < buffer.buffer_size or not isinstance(full, bool):
        raise ValueError(f"the buffer's position must be pos in [0, {buffer.buffer_size}) and full True or False, got {position!r}")
    return int(buffer.buffer_size if full else pos)


def _int_array(value: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    array = np.array(value)
    if array.shape != shape or array.dtype.kind not in "iu":
        raise ValueError(f"{name!r} must be {shape} ints, got {value!r}")
    return array.astype(np.int64)


def _read_array(archive: zipfile.ZipFile, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    expected = int(np.prod(shape)) * np.dtype(dtype).itemsize + NPY_HEADER_BYTES
    data = read_member(archive, name, ArchiveLimits(max_member_bytes=expected))
    array = np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
    if array.shape != tuple(shape) or array.dtype != dtype:
        raise ValueError(f"{name} holds {array.dtype} {array.shape}, expected {np.dtype(dtype)} {tuple(shape)}")
    return array


def _read_tensors(archive: zipfile.ZipFile, max_bytes: int) -> dict[str, torch.Tensor]:
    return safetensors.torch.load(read_member(archive, TENSORS, ArchiveLimits(max_member_bytes=max_bytes)))


def _take(tensors: dict[str, torch.Tensor], key: str, like: torch.Tensor) -> torch.Tensor:
    value = tensors.pop(key)
    if value.shape != like.shape or value.dtype != like.dtype:
        raise ValueError(f"tensor {key!r} is {value.dtype} {tuple(value.shape)}, expected {like.dtype} {tuple(like.shape)}")
    return value


def _restore_tensors(model: OffPolicyAlgorithm, tensors: dict[str, torch.Tensor]) -> None:
    tensors = dict(tensors)
    policy = model.policy.state_dict()
    model.policy.load_state_dict({key: _take(tensors, f"policy/{key}", value) for key, value in policy.items()})
    for name, optimizer in _optimizers(model).items():
        params = [p for group in optimizer.param_groups for p in group["params"]]
        prefix = f"optimizer/{name}/"
        saved: dict[int, dict[str, torch.Tensor]] = {}
        for key in [k for k in tensors if k.startswith(prefix)]:
            index_text, _, field = key[len(prefix) :].partition("/")
            index = int(index_text)
            if not 0 <= index < len(params) or field not in ("step", "exp_avg", "exp_avg_sq"):
                raise ValueError(f"tensor {key!r} names no state of the {name} optimiser")
            like = torch.zeros((), dtype=torch.float32) if field == "step" else params[index].detach()
            saved.setdefault(index, {})[field] = _take(tensors, key, like)
        optimizer.load_state_dict({"state": saved, "param_groups": optimizer.state_dict()["param_groups"]})
    log_ent_coef = getattr(model, "log_ent_coef", None)
    if isinstance(log_ent_coef, torch.Tensor):
        with torch.no_grad():
            log_ent_coef.copy_(_take(tensors, "log_ent_coef", log_ent_coef.detach()))
    torch.set_rng_state(_take(tensors, "rng/torch", torch.get_rng_state()))
    if tensors:
        raise ValueError(f"tensors this model does not have: {sorted(tensors)[:5]}")


def _replay_envs(model: OffPolicyAlgorithm, records: Any, last: dict[str, np.ndarray]) -> None:
    env = _vec_env(model)
    if not isinstance(records, list) or len(records) != env.num_envs:
        raise ValueError(f"'envs' must hold one reset record per training env ({env.num_envs})")
    observations = [env.env_method("replay_reset", record, indices=[i])[0] for i, record in enumerate(records)]
    replayed = _stack_observations(observations)
    for key, value in last.items():
        if key not in replayed or not np.array_equal(replayed[key].astype(value.dtype), value):
            raise ValueError(
                f"the training envs, their last resets replayed, observe other values than the saved ones ({key or 'observation'}): "
                "the file does not match these envs"
            )
    model._last_obs = last.get("", last)  # a Box space's observations sit under ""
    model._last_episode_starts = np.ones(env.num_envs, dtype=bool)


def _restore_generators(model: OffPolicyAlgorithm, rng: Any) -> None:
    if not isinstance(rng, dict) or set(rng) != {"numpy", "python", "action_space"}:
        raise ValueError("'rng' must hold the 'numpy', 'python' and 'action_space' generators")
    name, keys, pos, has_gauss, cached = rng["numpy"]
    np.random.set_state((name, _int_array(keys, (624,), "numpy keys").astype(np.uint32), int(pos), int(has_gauss), float(cached)))
    version, internal, gauss = rng["python"]
    random.setstate((int(version), tuple(int(x) for x in internal), None if gauss is None else float(gauss)))
    model.action_space.np_random.bit_generator.state = rng["action_space"]
