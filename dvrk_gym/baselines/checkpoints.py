"""Save a trained agent as stable-baselines3's zip plus a JSON of its settings; load its weights.

:func:`save_agent` writes ``<name>.zip`` with SB3's ``save`` (usable by ``SAC.load`` and
friends) and ``<name>.json`` beside it: the training config, the policy's network
settings, the goal scaling and the env steps trained. :func:`load_agent` does not use
SB3's ``load``, which unpickles (cloudpickle) part of the zip and so can run code from a
crafted file: it rebuilds the model from the JSON and reads only the policy's weights
(``policy.pth`` inside the zip) with ``torch.load(..., weights_only=True)``. Sizes are
bounded before anything is built or inflated: the settings JSON's size, the network the
settings describe (:func:`check_policy_kwargs`), and the zip's declared and actual member
sizes (:data:`AGENT_FILE_LIMITS`). Even so, only load files this tool wrote, or that you trust.

The JSON also records which dvrk_gym trained the agent (its source fingerprint,
:func:`~dvrk_gym.utils.source_fingerprint.source_fingerprint`), and the world the agent learnt in, in full (:func:`env_record`: every
``gym.make`` keyword of its env, defaults included, and the cable bias its preset named).
A later version whose defaults differ (the paper's ``contact``, say) evaluates the agent
with the recorded values, and :attr:`LoadedAgent.env_changes` says what differed.
"""

from __future__ import annotations

import dataclasses
import io
import json
import pickle
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from stable_baselines3.common.base_class import BaseAlgorithm

from dvrk_gym.baselines.agents import ALGORITHMS, check_policy_kwargs
from dvrk_gym.baselines.training import TrainConfig, TrainResult, make_agent_env
from dvrk_gym.baselines.wrappers import GOAL_CENTER_M, GOAL_HALF_RANGE_M
from dvrk_gym.envs import ENV_CONFIGS
from dvrk_gym.sim.robot.bias import resolve_bias
from dvrk_gym.utils.atomic import atomic_path, atomic_write_json, file_sha256, read_json
from dvrk_gym.utils.bounded_zip import ArchiveLimits, open_archive, read_member
from dvrk_gym.utils.checks import check_int
from dvrk_gym.utils.run_folder import flatten_settings
from dvrk_gym.utils.source_fingerprint import SourceFingerprint, source_fingerprint

FORMAT = "dvrk_gym.baselines/1"
"""Tag of the settings JSON, checked on load."""
POLICY_WEIGHTS = "policy.pth"
"""The member of SB3's zip that holds the policy's state dict."""
AGENT_FILE_LIMITS = ArchiveLimits(max_file_bytes=512 * 2**20, max_members=64, max_member_bytes=256 * 2**20, max_total_bytes=512 * 2**20)
"""What an agent's zip may hold (a 256 x 256 SAC's is about 3 MB: the policy 1.4 MB, the
optimisers' state the rest; its replay buffer not included)."""
MAX_SETTINGS_BYTES = 2**20
"""The largest settings JSON read, bytes."""
DISPLAY_ONLY = ("render_resolution", "renderer")
"""Env keywords that change only what ``render()`` shows, left out of :attr:`LoadedAgent.env_changes`."""


@dataclass(frozen=True)
class LoadedAgent:
    """An agent read back by :func:`load_agent`.

    Attributes:
        model: the model, with the trained policy weights (no replay buffer, no optimiser state).
        config: its training settings (the env to evaluate it on follows from them).
        env_steps: env steps (robot moves) it was trained with.
        path: the zip it came from.
        env_changes: how this version's env differs from the one the agent learnt in: the
            ``gym.make`` keyword (``bias_config``: the instrument; ``env``: nothing recorded)
            -> one line (empty: none). Keywords whose default changed are set back to the
            recorded values in ``config.env_overrides``; a changed instrument is only noted.
        source: the dvrk_gym that trained it (None: not recorded, a file saved before it was).
        name: its label, when one was given (:func:`distinct_labels`); None: :attr:`label`'s own.
    """

    model: BaseAlgorithm
    config: TrainConfig
    env_steps: int
    path: Path
    env_changes: dict[str, str] = field(default_factory=dict)
    source: SourceFingerprint | None = None
    name: str | None = None

    @property
    def label(self) -> str:
        """A short name for tables: the agent, its budget and seed (or the ``name`` given)."""
        return self.name if self.name is not None else f"{self.config.agent} ({self.env_steps} steps, seed {self.config.seed})"


def distinct_labels(agents: Sequence[LoadedAgent]) -> list[LoadedAgent]:
    """The agents, those that share a label named apart by the training settings that differ
    among them (``"sac (300 steps, seed 0; bias 'severe')"``), or by their files when none does.

    Raises:
        ValueError: one file given twice.
    """
    paths = [agent.path.resolve() for agent in agents]
    repeated = sorted({str(path) for path in paths if paths.count(path) > 1})
    if repeated:
        raise ValueError(f"{repeated} given more than once; give each model once")
    named = list(agents)
    for label in {agent.label for agent in agents}:
        group = [i for i, agent in enumerate(agents) if agent.label == label]
        if len(group) < 2:
            continue
        settings = [flatten_settings(agents[i].config.to_dict()) for i in group]
        differing = sorted({key for flat in settings for key in flat if len({repr(other.get(key)) for other in settings}) > 1})
        for i, flat in zip(group, settings):
            apart = ", ".join(f"{key} {flat.get(key)!r}" for key in differing) if differing else str(agents[i].path)
            named[i] = dataclasses.replace(agents[i], name=f"{label[:-1]}; {apart})")
    return named


def settings_path(model_path: Path) -> Path:
    """The settings JSON beside a model zip."""
    return Path(model_path).with_suffix(".json")


def save_agent(result: TrainResult, path: Path) -> Path:
    """Write ``result.model`` to ``path`` (a .zip) and its settings to the .json beside it.

    Returns:
        The zip's path.
    """
    path = Path(path).with_suffix(".zip")
    settings = {
        "format": FORMAT,
        "config": result.config.to_dict(),
        "policy_kwargs": _policy_kwargs(result.model),
        "goal_scaling": {"center_m": list(GOAL_CENTER_M), "half_range_m": GOAL_HALF_RANGE_M},
        "env": env_record(result.config),
        "env_steps": result.env_steps,
        "train_seconds": result.train_seconds,
        "steps_per_second": result.steps_per_second,
        "source": source_fingerprint().to_json(),
    }  # built before anything is written: a setting that cannot be saved leaves the old files as they were
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        result.model.save(temporary)
        settings["zip_sha256"] = _zip_sha256(Path(temporary))
    atomic_write_json(settings_path(path), settings, indent=1)
    return path


def _zip_sha256(path: Path) -> str:
    """The SHA-256 of an agent's zip, a regular file of at most :data:`AGENT_FILE_LIMITS`' file size."""
    return file_sha256(path, AGENT_FILE_LIMITS.max_file_bytes, "an agent's zip")


def env_record(config: TrainConfig) -> dict[str, Any]:
    """The world an agent of ``config`` learns in, as JSON values: ``id`` (its env),
    ``kwargs`` (every field of its env's config, the one ``gym.make`` builds from the
    agent's keywords over the env's defaults) and ``bias_config`` (the :class:`~dvrk_gym.sim.robot.bias.BiasConfig` its bias
    preset stands for in this version).

    Raises:
        ValueError: ``config``'s env keywords do not make a valid env config.
    """
    env_config = ENV_CONFIGS[config.spec.env_id](**config.env_kwargs())
    kwargs = dataclasses.asdict(env_config)
    record = {"id": config.spec.env_id, "kwargs": kwargs, "bias_config": dataclasses.asdict(resolve_bias(env_config.bias))}
    return json.loads(json.dumps(record))


def _agrees(recorded: Any, current: Any) -> bool:
    """Whether a recorded value is the current one; nested settings (dicts) are compared on the
    fields both have, so a field added since (at its default) is no contradiction."""
    if isinstance(recorded, dict) and isinstance(current, dict):
        return all(_agrees(recorded[key], current[key]) for key in recorded.keys() & current.keys())
    return bool(recorded == current)


def _recorded_world(config: TrainConfig, recorded: Any) -> tuple[TrainConfig, dict[str, str]]:
    """``config`` with the recorded values of every env keyword whose default has changed, and
    the differences between the recorded world and this version's: keyword (``bias_config``
    for the instrument) -> one line.

    Raises:
        ValueError: the record is mangled, or contradicts ``config`` on a keyword ``config`` sets.
    """
    if recorded is None:
        return config, {"env": f"its settings predate recorded envs: evaluated on this version's {config.spec.env_id} defaults"}
    if not isinstance(recorded, dict) or not isinstance(recorded.get("kwargs"), dict) or not isinstance(recorded.get("bias_config"), dict):
        raise ValueError(f"env must be an object with 'kwargs' and 'bias_config' objects, got {recorded!r}"[:300])
    if recorded.get("id") != config.spec.env_id:
        raise ValueError(f"env id {recorded.get('id')!r}, but agent {config.agent!r} learns {config.spec.env_id!r}")
    current = env_record(config)
    mine, now = recorded["kwargs"], current["kwargs"]
    for key, given in config.env_kwargs().items():  # set by the training settings themselves: the record must agree
        if key in mine and not _agrees(mine[key], now[key]):
            if isinstance(given, dict) and _agrees(mine[key], given):  # some fields given, the rest defaults that changed since
                continue
            raise ValueError(f"env records {key} = {mine[key]!r}, but the training settings give {now[key]!r}")
    restore, changes = {}, {}
    for key in sorted((set(mine) | set(now)) - set(DISPLAY_ONLY)):
        if key not in now:
            changes[key] = f"{key} was {mine[key]!r} in training; this version has no such setting"
        elif key not in mine:
            changes[key] = f"{key} was not recorded in training; evaluated with this version's {now[key]!r}"
        elif mine[key] != now[key]:
            restore[key] = mine[key]
            changes[key] = f"{key}: learnt with {mine[key]!r}, this version's default is {now[key]!r}; evaluated with {mine[key]!r}"
    was, is_now = recorded["bias_config"], current["bias_config"]
    drifted = sorted(k for k in set(was) | set(is_now) if was.get(k) != is_now.get(k))
    if drifted:
        fields = ", ".join(drifted)
        changes["bias_config"] = f"the {config.bias!r} instrument changed since training ({fields}); evaluated on this version's"
    return dataclasses.replace(config, env_overrides={**config.env_overrides, **restore}), changes


def _policy_kwargs(model: BaseAlgorithm) -> dict[str, Any]:
    kwargs = dict(model.policy_kwargs)
    try:
        json.dumps(kwargs)
    except TypeError as error:
        raise ValueError(f"policy_kwargs must be plain JSON values to be saved safely, got {kwargs!r}: {error}") from None
    return check_policy_kwargs(kwargs)


def _read_settings(path: Path) -> dict[str, Any]:
    json_path = settings_path(path)
    if not Path(path).exists():
        raise FileNotFoundError(f"no model file {path}")
    if not json_path.exists():
        raise FileNotFoundError(f"{json_path} is missing: models are saved by 'dvrk-gym baseline train' as a .zip and a .json side by side")
    try:
        settings = read_json(json_path, max_bytes=MAX_SETTINGS_BYTES)  # a regular file of bounded size, or a ValueError naming it
    except ValueError as error:
        raise ValueError(f"{error}; was it cut short? Train the agent again") from None
    if not isinstance(settings, dict):
        raise ValueError(f"{json_path} holds {type(settings).__name__}, not a dvrk_gym baseline settings object")
    if settings.get("format") != FORMAT:
        raise ValueError(f"{json_path} is not a dvrk_gym baseline settings file (format {settings.get('format')!r}, expected {FORMAT!r})")
    try:
        scaling = settings["goal_scaling"]
        if tuple(scaling["center_m"]) != tuple(GOAL_CENTER_M) or scaling["half_range_m"] != GOAL_HALF_RANGE_M:
            raise ValueError(
                f"{path} was trained with goal scaling {scaling}, but this version scales by {GOAL_CENTER_M}, {GOAL_HALF_RANGE_M}"
            )
        check_policy_kwargs(settings["policy_kwargs"])
        check_int("env_steps", settings["env_steps"], 0)
        if not isinstance(settings["config"], dict):
            raise ValueError(f"config must be an object, got {settings['config']!r}")
    except (KeyError, TypeError) as error:
        raise ValueError(f"{json_path} lacks or mangles a setting ({type(error).__name__}: {error})") from None
    except ValueError as error:
        raise ValueError(f"{json_path}: {error}") from None
    return settings


def _policy_weights(path: Path) -> dict[str, torch.Tensor]:
    """The policy's state dict, read within :data:`AGENT_FILE_LIMITS`, tensors only (no pickled objects)."""
    with open_archive(path, AGENT_FILE_LIMITS) as archive:
        if POLICY_WEIGHTS not in archive.namelist():
            raise ValueError(f"{path} holds no {POLICY_WEIGHTS}; is it a stable-baselines3 zip?")
        buffer = io.BytesIO(read_member(archive, POLICY_WEIGHTS, AGENT_FILE_LIMITS))
    try:
        weights = torch.load(buffer, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, ValueError) as error:
        # torch's own words would advise loading with weights_only=False, that is, running the file's code
        why = "it holds objects other than tensors" if isinstance(error, pickle.UnpicklingError) else f"{type(error).__name__}"
        raise ValueError(f"{path}: {POLICY_WEIGHTS} is not a plain tensor state dict ({why}); refused, never unpickled") from None
    if not isinstance(weights, dict) or not all(isinstance(value, torch.Tensor) for value in weights.values()):
        raise ValueError(f"{path}: {POLICY_WEIGHTS} is not a state dict of tensors")
    broken = [name for name, value in weights.items() if value.is_floating_point() and not bool(torch.isfinite(value).all())]
    if broken:  # else the first action fails in torch's distribution, naming neither the file nor the weights
        raise ValueError(f"{path}: {POLICY_WEIGHTS} holds weights that are not finite ({', '.join(map(str, broken[:3]))})")
    return weights


def load_agent(path: Path) -> LoadedAgent:
    """Rebuild an agent saved by :func:`save_agent`, reading only tensors from the zip.

    Raises:
        FileNotFoundError: the zip or its settings JSON is missing.
        ValueError: a folder; the files are not an agent of this tool, do not match this
            version, or the zip is not the one its settings were written with.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give the agent's model.zip (its model.json beside it)")
    settings = _read_settings(path)
    recorded_digest = settings.get("zip_sha256")  # absent from files saved before it was recorded
    if recorded_digest is not None and recorded_digest != _zip_sha256(path):
        raise ValueError(
            f"{path} is not the zip {settings_path(path).name} was written with (another run's, changed since, "
            "or a save cut short): train the agent again, or put its own files side by side"
        )
    try:
        config = TrainConfig(**settings["config"])
        config, env_changes = _recorded_world(config, settings.get("env"))
    except (TypeError, ValueError) as error:
        raise ValueError(f"{settings_path(path)}: bad training settings: {error}") from None
    try:
        env = make_agent_env(config, training=False)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{settings_path(path)}: this version cannot build the env the agent learnt in: {error}") from None
    try:
        algorithm = ALGORITHMS[config.spec.algorithm]
        model = algorithm("MultiInputPolicy", env, policy_kwargs=settings["policy_kwargs"], device="cpu", **_inference_only(algorithm))
        model.policy.load_state_dict(_policy_weights(path))
    except RuntimeError as error:
        raise ValueError(f"the weights in {path} do not fit the network its settings describe: {error}") from None
    finally:
        env.close()
    model.policy.set_training_mode(False)
    return LoadedAgent(model, config, int(settings["env_steps"]), path, env_changes, SourceFingerprint.from_json(settings.get("source")))


def finished_agent(path: Path, config: TrainConfig) -> LoadedAgent | None:
    """The agent saved at ``path`` if it is ``config``'s training, trained by this very dvrk_gym; else None.

    A run that trains several agents and was killed uses it to keep those it had finished. An
    agent is kept only when its zip and settings are there and whole (:func:`load_agent`), its
    recorded training settings are ``config``'s, and its recorded source fingerprint is this
    process's, so results never mix agents trained by other code. Anything else (no file, a
    damaged one, other settings, other code, a file saved before the source was recorded)
    gives None: train it again.
    """
    path = Path(path)
    try:
        recorded = _read_settings(path)
        if recorded["config"] != json.loads(json.dumps(config.to_dict())):
            return None
        if SourceFingerprint.from_json(recorded.get("source")) != source_fingerprint():
            return None
        agent = load_agent(path)
    except (OSError, ValueError):
        return None
    return agent if not agent.env_changes else None


def _inference_only(algorithm: type[BaseAlgorithm]) -> dict[str, Any]:
    """Constructor keywords that keep an inference-only model small (a one-row buffer)."""
    if "buffer_size" in algorithm.__init__.__code__.co_varnames:
        return {"buffer_size": 1}
    return {}
