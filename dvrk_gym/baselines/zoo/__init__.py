"""RL Zoo hyperparameters for dvrk_gym's envs, shipped with the package (for ``--algo sac``).

RL Zoo reads a Python package's ``hyperparams`` dict when ``--conf-file`` names one, so a
plain RL Zoo install trains and replays the envs with no file of the user's::

    python -m rl_zoo3.train --algo sac --env dvrk_gym/GridTouch-v0 --gym-packages dvrk_gym \\
        --conf-file dvrk_gym.baselines.zoo -f logs
    python -m rl_zoo3.enjoy --algo sac --env dvrk_gym/GridTouch-v0 --gym-packages dvrk_gym \\
        -f logs --no-render -n 35

The settings are the package's own agents' (:data:`dvrk_gym.baselines.agents.AGENTS`):
GridTouch-v0 is ``sac_her`` (SAC + HER through :func:`~dvrk_gym.baselines.wrappers.wrap_grid_touch`)
and Debridement-v0 is ``sac_pick``, each for the two-phase calibrator's 5,476 robot moves.
RL Zoo takes policy and replay-buffer settings as strings, which it evaluates.
"""

from __future__ import annotations

from typing import Any

from dvrk_gym.baselines.agents import AGENTS
from dvrk_gym.baselines.budgets import CALIBRATOR_MOVES


def _zoo_settings(agent: str, wrapper: str, wrapper_kwargs: dict[str, Any]) -> dict[str, Any]:
    """One agent's row of :data:`AGENTS` in RL Zoo's words."""
    spec = AGENTS[agent]
    settings: dict[str, Any] = {key: value for key, value in spec.hyperparameters.items() if key != "policy_kwargs"}
    settings.update(
        policy="MultiInputPolicy",
        n_timesteps=CALIBRATOR_MOVES,
        env_wrapper=[{wrapper: wrapper_kwargs}],
        env_kwargs=dict(spec.env_kwargs),
        policy_kwargs=repr(spec.hyperparameters.get("policy_kwargs", {})),
    )
    if spec.her:
        settings.update(
            replay_buffer_class="HerReplayBuffer",
            replay_buffer_kwargs="dict(n_sampled_goal=4, goal_selection_strategy='future')",
        )
    return settings


hyperparams: dict[str, dict[str, Any]] = {
    "dvrk_gym/GridTouch-v0": _zoo_settings("sac_her", "dvrk_gym.baselines.wrappers.wrap_grid_touch", {"training_yaws": "paper"}),
    "dvrk_gym/Debridement-v0": _zoo_settings("sac_pick", "dvrk_gym.baselines.picking.wrap_debridement", {}),
}
"""RL Zoo's settings per env id, for SAC."""
