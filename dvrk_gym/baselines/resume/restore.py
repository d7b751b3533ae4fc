"""Put a saved training state back into a model built afresh, checking everything before it is used.

The file is the one :func:`~dvrk_gym.baselines.resume.state_file.save_training_state` writes.
Sizes are bounded before anything is read or allocated: the zip's declared member sizes
against what the model's own replay buffer and networks can hold, each ``.npy`` member's
header (shape, dtype) against the model's before its array is made. The source fingerprint,
the libraries' versions and the settings must be the ones of this run; every tensor must
have the shape and dtype of the model's; and the envs' replayed resets must observe the
saved observation bit for bit.
"""

from __future__ import annotations

import io
import json
import math
import random
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import safetensors.torch
import torch
from safetensors import SafetensorError
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.her import HerReplayBuffer

from dvrk_gym.baselines.resume.state_file import (
    ARRAYS,
    FORMAT,
    LIBRARIES,
    MAX_JSON_BYTES,
    NPY_HEADER_BYTES,
    STATE_JSON,
    TENSOR_SLACK_BYTES,
    TENSORS,
    TrainingStateError,
    buffer_arrays,
    check_supported,
    library_versions,
    model_optimizers,
    stack_observations,
    training_envs,
)
from dvrk_gym.utils.bounded_zip import ArchiveLimitError, ArchiveLimits, open_archive, read_member, read_npy_header
from dvrk_gym.utils.checks import check_int
from dvrk_gym.utils.source_fingerprint import SourceFingerprint, source_fingerprint

MT19937_WORDS = 624
"""The words of numpy's legacy generator's state; its position runs from 0 to this."""


def restore_training_state(path: str | Path, model: Any, config: dict[str, Any]) -> dict[str, Any]:
    """Put the training state saved at ``path`` back into ``model``; its ``progress`` record.

    ``model`` must be freshly built with the same settings (``config``) on training envs
    wrapped as :func:`save_training_state` wants, and not yet trained. After this, continue
    with ``model.learn(remaining, reset_num_timesteps=False)``. If it raises, the model, its
    envs and the global random generators may be partly restored: discard them.

    Written against stable-baselines3 2.9: it sets ``_last_obs``, ``_n_updates``,
    ``_episode_num`` and HER's ``_current_ep_start``, private attributes of that version.

    Raises:
        FileNotFoundError: no such file.
        TrainingStateError: the file is not a training state of these settings written by
            this version of dvrk_gym with these libraries (:data:`LIBRARIES`), or it is
            damaged, or it holds values that do not fit this model and its envs (the message
            says which). The checks catch damage and states that do not fit; a deliberately
            edited value that still fits (a generator's state, say) is not detected.
    """
    model = check_supported(model)
    path = Path(path)
    buffer = model.replay_buffer
    arrays = buffer_arrays(model)
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
            starts = _int_array(state["buffer"].get("current_ep_start"), buffer._current_ep_start.shape, "current_ep_start")
            if not ((starts >= 0) & (starts < buffer.buffer_size)).all():
                raise ValueError(f"'current_ep_start' must lie in [0, {buffer.buffer_size}), got {starts.tolist()}")
            buffer._current_ep_start = starts
        model.num_timesteps = _count(state, "num_timesteps")
        model._n_updates = _count(state, "n_updates")
        model._episode_num = _count(state, "episode_num")
        _replay_envs(model, state["envs"], last)
        _restore_generators(model, state["rng"])
    except (
        ArchiveLimitError,
        SafetensorError,
        KeyError,
        TypeError,
        ValueError,
        RuntimeError,
        IndexError,
        ArithmeticError,
        zlib.error,
    ) as error:
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
    n_envs = training_envs(model).num_envs
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
    libraries = library_versions()
    if state.get("libraries") != libraries:
        written_with: dict[str, Any] = state["libraries"] if isinstance(state.get("libraries"), dict) else {}
        differ = [
            f"{name} {written_with.get(name)} there, {libraries[name]} here"
            for name in LIBRARIES
            if written_with.get(name) != libraries[name]
        ]
        raise TrainingStateError(
            f"{archive.filename}: written with other libraries ({'; '.join(differ)}): a resume would not continue the same run; "
            "resume it where it was written, or delete the file to train afresh"
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
    return check_int(repr(key), state.get(key), 0, 10**12)


def _check_buffer_position(position: Any, buffer: Any) -> int:
    if not isinstance(position, dict) or not isinstance(position.get("full"), bool):
        raise ValueError(f"the buffer's position must be a dict with 'pos' and 'full' (True or False), got {position!r}")
    pos = check_int("the buffer's position 'pos'", position.get("pos"), 0, buffer.buffer_size - 1)
    return int(buffer.buffer_size if position["full"] else pos)


def _int_array(value: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    array = np.array(value)
    if array.shape != shape or array.dtype.kind not in "iu":
        raise ValueError(f"{name!r} must be {shape} ints, got {value!r}")
    return array.astype(np.int64)


def _read_array(archive: zipfile.ZipFile, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    """An ``.npy`` member of the expected shape and dtype; its header is checked before any array is allocated."""
    expected = int(np.prod(shape)) * np.dtype(dtype).itemsize
    data = read_member(archive, name, ArchiveLimits(max_member_bytes=expected + NPY_HEADER_BYTES))
    stream = io.BytesIO(data)
    found_shape, fortran_order, found_dtype = read_npy_header(stream, name)
    if tuple(found_shape) != tuple(shape) or found_dtype != np.dtype(dtype) or fortran_order:
        raise ValueError(f"{name} holds {found_dtype} {tuple(found_shape)}, expected {np.dtype(dtype)} {tuple(shape)} in C order")
    body = data[stream.tell() :]
    if len(body) != expected:
        raise ValueError(f"{name} holds {len(body)} bytes of data, expected {expected}")
    return np.frombuffer(body, dtype=found_dtype).reshape(shape).copy()


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
    for name, optimizer in model_optimizers(model).items():
        params = [p for group in optimizer.param_groups for p in group["params"]]
        prefix = f"optimizer/{name}/"
        saved: dict[int, dict[str, torch.Tensor]] = {}
        for key in [k for k in tensors if k.startswith(prefix)]:
            index_text, _, field = key[len(prefix) :].partition("/")
            index = int(index_text)
            if not 0 <= index < len(params) or not field:
                raise ValueError(f"tensor {key!r} names no state of the {name} optimiser")
            like = params[index].detach() if tensors[key].dim() else torch.zeros((), dtype=torch.float32)  # a moment, or a step count
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
    env = training_envs(model)
    if not isinstance(records, list) or len(records) != env.num_envs:
        raise ValueError(f"'envs' must hold one reset record per training env ({env.num_envs})")
    observations = []
    for index, record in enumerate(records):
        observation, refusal = env.env_method("replay_reset", record, indices=[index])[0]
        if refusal is not None:
            raise ValueError(f"training env {index} refused its recorded reset ({refusal})")
        observations.append(observation)
    replayed = stack_observations(observations)
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
    # numpy does not check the position against its 624 words: one past them draws garbage, far past them crashes
    if name != "MT19937" or not 0 <= int(pos) <= MT19937_WORDS or int(has_gauss) not in (0, 1) or not math.isfinite(float(cached)):
        raise ValueError(f"'rng.numpy' is not an MT19937 state (position in [0, {MT19937_WORDS}], a 0/1 flag, a finite float)")
    words = _int_array(keys, (MT19937_WORDS,), "numpy keys")
    if not ((words >= 0) & (words < 2**32)).all():
        raise ValueError("'numpy keys' must be 32-bit words")
    np.random.set_state((name, words.astype(np.uint32), int(pos), int(has_gauss), float(cached)))
    version, internal, gauss = rng["python"]
    random.setstate((int(version), tuple(int(x) for x in internal), None if gauss is None else float(gauss)))
    model.action_space.np_random.bit_generator.state = rng["action_space"]
