"""The training envs' state at an episode boundary, recorded at every reset and replayed on resume.

A training env is a stack: the dvrk_gym env, then wrappers. Between two episodes its whole
memory is what each layer carries into the next reset: the env's
:meth:`~dvrk_gym.envs.base.DvrkEnv.carried_state` (random generator, cable history,
commanded joints, its own ``carried_attributes``) and each wrapper's ``carried_attributes``
(the training yaw schedule's episode count, say). Everything else is rebuilt by the reset.

:class:`ResetRecorder`, the outermost layer of every training env, records that memory as
each reset begins. A resumed training builds its envs afresh and replays the last reset of
each (:meth:`ResetRecorder.replay_reset`): the same memory, the same seed and options, so the
same observation, bit for bit; the caller checks that it is.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from dvrk_gym.envs.base import DvrkEnv


def _layers(env: gym.Env) -> Iterator[gym.Env]:
    """``env`` and every env it wraps, outermost first."""
    layer = env
    while isinstance(layer, gym.Wrapper):
        yield layer
        layer = layer.env
    yield layer


def _layer_state(layer: gym.Env) -> dict[str, Any]:
    if isinstance(layer, DvrkEnv):
        return layer.carried_state()
    return {name: getattr(layer, name) for name in getattr(type(layer), "carried_attributes", ())}


def stack_state(env: gym.Env) -> list[dict[str, Any]]:
    """What every layer of ``env`` carries into its next reset, outermost first: ``{"layer":
    class name, "state": JSON values}``."""
    return [{"layer": type(layer).__name__, "state": _layer_state(layer)} for layer in _layers(env)]


def restore_stack_state(env: gym.Env, layers: Any) -> None:
    """Give each layer of ``env`` its part of a :func:`stack_state` of a stack built the same way.

    Raises:
        ValueError: ``layers`` does not describe a stack of the same layers, or a layer's state is invalid.
    """
    stack = list(_layers(env))
    names = [type(layer).__name__ for layer in stack]
    if not isinstance(layers, list) or not all(isinstance(entry, dict) and set(entry) == {"layer", "state"} for entry in layers):
        raise ValueError("an env's recorded state must be a list of {'layer', 'state'} entries")
    recorded = [entry["layer"] for entry in layers]
    if recorded != names:
        raise ValueError(f"the recorded env was the stack {recorded}; this one is {names}")
    for layer, entry in zip(stack, layers):
        state = entry["state"]
        if isinstance(layer, DvrkEnv):
            layer.restore_carried_state(state)
            continue
        expected = set(getattr(type(layer), "carried_attributes", ()))
        if not isinstance(state, dict) or set(state) != expected:
            raise ValueError(f"{type(layer).__name__} carries {sorted(expected)}, the record holds {state!r}")
        check = getattr(layer, "_check_carried_attributes", None)
        if check is not None:
            check(state)  # before any is set
        for name, value in state.items():
            setattr(layer, name, value)


class ResetRecorder(gym.Wrapper):
    """Record, as each reset begins, what the env carries into it (:func:`stack_state`) and
    the reset's seed and options; replay that reset on an env built afresh.

    It changes nothing the env does: observations, rewards and actions pass through.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._last_reset: dict[str, Any] | None = None
        self._steps_since_reset = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        record = {"seed": int(seed) if isinstance(seed, np.integer) else seed, "options": options, "layers": stack_state(self.env)}
        result = self.env.reset(seed=seed, options=options)
        # Taken before the reset changed anything, kept once the env took it: a refused reset
        # leaves the last one's record (and the episode it started) as they were.
        self._last_reset, self._steps_since_reset = record, 0
        return result

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        self._steps_since_reset += 1
        return self.env.step(action)

    def between_episodes(self) -> bool:
        """Whether the env has been reset and not stepped since: its state is then its last reset's."""
        return self._last_reset is not None and self._steps_since_reset == 0

    def last_reset(self) -> dict[str, Any]:
        """The last reset's record, JSON values (copied): ``{"seed", "options", "layers"}``.

        Raises:
            RuntimeError: the env has not been reset.
            ValueError: the reset's options are not JSON values.
        """
        if self._last_reset is None:
            raise RuntimeError("the env has not been reset: no reset to record")
        try:
            return json.loads(json.dumps(self._last_reset, allow_nan=False))
        except (TypeError, ValueError) as error:
            raise ValueError(f"the last reset's record cannot be saved as JSON ({error})") from None

    def replay_reset(self, record: Any) -> tuple[Any, str | None]:
        """Take up a :meth:`last_reset` record and reset as it did.

        Returns:
            (the observation, None), or (None, why the record was refused): a refusal is
            returned, not raised, so that a vector env's worker process survives it and the
            caller can say what was wrong.
        """
        try:
            if not isinstance(record, dict) or set(record) != {"seed", "options", "layers"}:
                raise ValueError("a reset record is a dict with keys 'seed', 'options' and 'layers'")
            seed, options = record["seed"], record["options"]
            if not (seed is None or (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**64)):
                raise ValueError(f"a reset record's seed must be None or an int in [0, 2**64), got {seed!r}")
            if not (options is None or isinstance(options, dict)):
                raise ValueError(f"a reset record's options must be None or a dict, got {options!r}")
            restore_stack_state(self.env, record["layers"])
            observation, _ = self.reset(seed=seed, options=options)
        except (ValueError, TypeError, KeyError, IndexError, ArithmeticError) as error:
            self._last_reset = None  # whatever was restored, this env is not between two known episodes
            return None, f"{type(error).__name__}: {error}"
        return observation, None
