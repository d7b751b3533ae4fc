"""Evaluate any policy on any dvrk_gym environment, with fixed seeds and the paper's metrics.

A policy is a callable from observation to action, a stable-baselines3 model (anything
with ``predict(observation, deterministic=True)``), or a
:class:`~dvrk_gym.calibration.policy.CalibratedPolicy`. Each episode's metrics are the
numeric scalars of its final ``info`` (for GridTouch: ``pixel_error``, ``mm_error``,
``is_success``...) plus its return and length; :func:`summarize` gives mean, standard
error, median, minimum and maximum.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

from dvrk_gym.utils.checks import check_int

Policy = Callable[[Any], np.ndarray]
Options = dict[str, Any] | Callable[[int], dict[str, Any]] | None
MAX_EPISODES = 1_000_000
"""The most episodes :func:`run_episodes` runs in one call."""


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluated episode.

    Attributes:
        index: the episode's position in the run.
        options: the reset options used.
        length: steps taken.
        total_reward: sum of rewards.
        metrics: numeric scalars of the final info (and ``return``, ``length``).
        final_info: the final info dict itself (may hold arrays and strings).
    """

    index: int
    options: dict[str, Any]
    length: int
    total_reward: float
    metrics: dict[str, float]
    final_info: dict[str, Any] = field(repr=False)


def as_policy(policy: Any) -> Policy:
    """Wrap a callable, a stable-baselines3 model or a CalibratedPolicy as obs -> action."""
    if hasattr(policy, "predict") and hasattr(policy, "observation_space"):  # SB3 model or policy
        return lambda observation: policy.predict(observation, deterministic=True)[0]
    if callable(policy):
        return policy
    raise TypeError(f"a policy must be callable or have predict(); got {type(policy).__name__}")


def load_policy_factory(spec: str) -> Callable[[gym.Env], Any]:
    """Import ``"package.module:factory"`` (from the import path or the current folder): a function taking the env, returning a policy."""
    module_name, _, attribute = spec.partition(":")
    if not module_name or not attribute or module_name.startswith("."):  # a relative import has no package to start from
        raise ValueError(f"--policy must look like 'package.module:factory', got {spec!r}")
    # The current folder too, as `python -m` would look: an installed command's import path
    # lacks it, so a policy file beside the user was not found.
    here = os.getcwd()
    added = here not in sys.path and "" not in sys.path
    if added:
        sys.path.insert(0, here)
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f"cannot import {module_name!r} for --policy (from the import path and the current folder): {error}") from None
    except Exception as error:  # the user's module fails as it loads (a SyntaxError names its file and line)
        raise ValueError(f"importing {module_name!r} for --policy raised {type(error).__name__}: {error}") from error
    finally:
        if added:
            sys.path.remove(here)
    try:
        factory = getattr(module, attribute)
    except AttributeError:
        raise ValueError(f"module {module_name!r} has no attribute {attribute!r}") from None
    if not callable(factory):
        raise ValueError(f"{spec!r} is not callable")
    _check_takes_env(factory, spec)
    return factory


def run_episodes(
    env: gym.Env,
    policy: Any,
    *,
    n_episodes: int,
    seed: int = 0,
    options: Options = None,
    progress: bool = True,
    description: str = "episodes",
) -> list[EpisodeResult]:
    """Run ``n_episodes`` of ``policy`` on ``env``.

    Args:
        env: the environment.
        policy: see :func:`as_policy`.
        n_episodes: how many episodes.
        seed: the first episode is reset with this seed, the rest continue its stream, so
            the whole run is reproducible.
        options: reset options, fixed or a function of the episode index.
        progress: show a progress bar.
        description: the progress bar's label.

    Raises:
        ValueError: ``n_episodes`` not an int in [1, ``MAX_EPISODES``], or a negative ``seed``.
    """
    n_episodes = check_int("n_episodes", n_episodes, 1, MAX_EPISODES)
    seed = check_int("seed", seed, 0)
    act = as_policy(policy)
    results = []
    for index in tqdm(range(n_episodes), desc=description, disable=not progress):
        episode_options = options(index) if callable(options) else dict(options or {})
        observation, info = env.reset(seed=seed if index == 0 else None, options=episode_options)
        total, length, done = 0.0, 0, False
        while not done:
            observation, reward, terminated, truncated, info = env.step(act(observation))
            total += float(reward)
            length += 1
            done = terminated or truncated
        metrics = {key: float(value) for key, value in info.items() if _is_scalar(value)}
        metrics.update({"return": total, "length": float(length)})
        results.append(EpisodeResult(index, episode_options, length, total, metrics, info))
    return results


def evaluate_policy(
    factory: str | Callable[[gym.Env], Any],
    env_id: str,
    *,
    n_episodes: int,
    seed: int = 0,
    options: Options = None,
    progress: bool = True,
    **env_kwargs: Any,
) -> list[EpisodeResult]:
    """Run a policy made for a fresh environment: ``factory(env)`` gives the policy.

    Args:
        factory: a function of the env returning the policy, or its ``"package.module:factory"``
            name (:func:`load_policy_factory`).
        env_id: the environment, e.g. ``"dvrk_gym/GridTouch-v0"``.
        n_episodes: how many episodes (:func:`run_episodes`).
        seed: the first episode's reset seed.
        options: reset options, fixed or a function of the episode index.
        progress: show a progress bar.
        **env_kwargs: ``gym.make`` keywords (``bias``, ``bias_seed``, ``camera_resolution``...).

    Raises:
        ValueError: the factory cannot be imported, or cannot be called with the env alone.
    """
    if isinstance(factory, str):
        make_policy = load_policy_factory(factory)  # checks it takes the env
    else:
        _check_takes_env(factory, factory)
        make_policy = factory
    env = gym.make(env_id, **env_kwargs)
    try:
        policy = make_policy(env)  # an error inside the factory is the factory's, raised as it is
        return run_episodes(env, policy, n_episodes=n_episodes, seed=seed, options=options, progress=progress)
    finally:
        env.close()


def _check_takes_env(make_policy: Callable[..., Any], factory: Any) -> None:
    """ValueError unless ``make_policy`` can be called with one positional argument (the env)."""
    if not callable(make_policy):
        raise ValueError(f"the policy factory {factory!r} is not callable")
    try:
        signature = inspect.signature(make_policy, follow_wrapped=False)
    except (TypeError, ValueError):  # no signature to read (some builtins): the call will tell
        return
    try:
        signature.bind(None)
    except TypeError as error:
        raise ValueError(f"the policy factory {factory!r} must take the env as its one argument and return a policy ({error})") from None


def _is_scalar(value: Any) -> bool:
    return isinstance(value, (bool, int, float, np.bool_, np.integer, np.floating)) and np.isfinite(float(value))


def summarize(values: Iterable[float]) -> dict[str, float]:
    """Mean, standard error of the mean, median, minimum, maximum and count."""
    array = np.asarray(list(values), dtype=float)
    if array.size == 0:
        raise ValueError("nothing to summarize")
    sem = float(array.std(ddof=1) / np.sqrt(array.size)) if array.size > 1 else 0.0
    return {
        "mean": float(array.mean()),
        "sem": sem,
        "median": float(np.median(array)),
        "min": float(array.min()),
        "max": float(array.max()),
        "n": float(array.size),
    }


def summarize_metric(results: list[EpisodeResult], name: str) -> dict[str, float]:
    """:func:`summarize` one metric over the episodes that report it."""
    values = [r.metrics[name] for r in results if name in r.metrics]
    if not values:
        raise ValueError(f"no episode reported {name!r}; metrics are {sorted(results[0].metrics) if results else []}")
    return summarize(values)
