"""Gymnasium environments of the dVRK experiment, registered as ``dvrk_gym/<Name>-v0``.

Each id is registered with its config's defaults as ``kwargs`` (``gym.spec(id).kwargs``:
every setting, as plain JSON values, nested settings as dicts and pairs as lists), so
``gym.make(id)`` and ``gym.make(id, **gym.spec(id).kwargs)`` make the same env, and a
keyword given to ``gym.make`` replaces its default. A keyword the env does not take raises
``TypeError`` naming the ones it takes; a bad value raises ``ValueError`` saying what is
allowed.

Each id is registered with ``disable_env_checker=True``: the envs check their own actions,
options and keywords (and the tests run Gymnasium's ``check_env`` on each), while Gymnasium's
passive checker, ``gym.make``'s default, marks its first ``reset`` as checked before running
it, so after a refused first reset (a mistyped option) its first ``step`` fails with
``TypeError: cannot unpack non-iterable NoneType`` (Gymnasium 1.4.0).
``gym.make(id, disable_env_checker=False)`` puts it back.

No env is registered with a ``max_episode_steps``: each ends its episodes itself.
CalibrationExploration-v0 truncates one after ``max_steps`` poses (93 by default, one of the
paper's Phase I trajectories; a registered limit of 93 cut a ``max_steps=200`` at 93,
silently), GridTouch-v0's one touch ends it (``terminated``), and Debridement-v0 terminates a
trial after ``max_picks`` picks, or truncates it after ``max_steps`` control steps in delta
mode. A time limit would mark the last touch or pick ``truncated`` too, which it is not
(and one of eight steps cut a delta-mode episode at 0.8 s). Give ``gym.make`` a
``max_episode_steps`` to cut episodes shorter.

The configs are read from modules that load neither PyBullet nor SciPy
(:mod:`~dvrk_gym.envs.configs`, :mod:`~dvrk_gym.envs.debridement_config`), so that
``import dvrk_gym`` stays light; the env classes load when an env is made.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import gymnasium as gym

from dvrk_gym.envs.configs import EnvConfig, ExplorationConfig, GridTouchConfig
from dvrk_gym.envs.debridement_config import DebridementConfig

ENV_ENTRY_POINTS = {
    "dvrk_gym/CalibrationExploration-v0": "dvrk_gym.envs.exploration:CalibrationExplorationEnv",
    "dvrk_gym/GridTouch-v0": "dvrk_gym.envs.grid_touch:GridTouchEnv",
    "dvrk_gym/Debridement-v0": "dvrk_gym.envs.debridement:DebridementEnv",
}
"""Each env id and the class that implements it."""
ENV_CONFIGS: dict[str, type[EnvConfig]] = {
    "dvrk_gym/CalibrationExploration-v0": ExplorationConfig,
    "dvrk_gym/GridTouch-v0": GridTouchConfig,
    "dvrk_gym/Debridement-v0": DebridementConfig,
}
"""Each env id and its config class (the class's ``config_class``; a test checks they agree)."""
EPISODE_STEPS: dict[str, int | None] = {
    "dvrk_gym/CalibrationExploration-v0": None,
    "dvrk_gym/GridTouch-v0": None,
    "dvrk_gym/Debridement-v0": None,
}
"""Each env's ``max_episode_steps`` for Gymnasium's TimeLimit: None, as each ends its episodes
itself (the exploration env truncates after its ``max_steps``)."""


def default_kwargs(config_class: type[EnvConfig]) -> dict[str, Any]:
    """The defaults of ``config_class`` as plain JSON values: what ``gym.spec(id).kwargs`` holds.

    Nested configs (Debridement-v0's ``timing`` and ``gripper``) become dicts of their fields
    and tuples become lists, as a JSON round trip gives them back; the config reads both
    forms, so these keywords build a config equal to ``config_class()``.
    """
    return json.loads(json.dumps(dataclasses.asdict(config_class())))


def register_envs() -> None:
    """Register every environment with Gymnasium (idempotent)."""
    for env_id, entry_point in ENV_ENTRY_POINTS.items():
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point=entry_point,
                max_episode_steps=EPISODE_STEPS[env_id],
                kwargs=default_kwargs(ENV_CONFIGS[env_id]),
                disable_env_checker=True,  # Gymnasium's passive checker breaks after a refused first reset (above)
            )
