"""The agents' names, environments and one-line descriptions, importable without torch or pybullet.

The command line builds its help and choices from here, so ``dvrk-gym baseline --help``
stays fast; :data:`dvrk_gym.baselines.agents.AGENTS` holds the full rows under the same names.
"""

from __future__ import annotations

GRID_TOUCH_ID = "dvrk_gym/GridTouch-v0"
DEBRIDEMENT_ID = "dvrk_gym/Debridement-v0"

AGENT_ENVS: dict[str, str] = {"sac_her": GRID_TOUCH_ID, "sac": GRID_TOUCH_ID, "sac_pick": DEBRIDEMENT_ID}
"""The env each agent learns."""
AGENT_DESCRIPTIONS: dict[str, str] = {
    "sac_her": "SAC + HER (future goals) on GridTouch-v0",
    "sac": "SAC on GridTouch-v0 (no relabelling)",
    "sac_pick": "SAC on Debridement-v0's pick target (one pick per step, shaped reward)",
}
"""One line per agent, for help texts and tables."""
