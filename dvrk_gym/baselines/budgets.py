"""The agents' names and envs, and their training budgets in robot moves, matched to the two-phase calibrator's.

Importable without torch or pybullet: the command line builds its help and choices from here.

The calibrator moves the robot 5,476 times: the paper's Phase I (57 trajectories of 93
commanded poses, 5,301 moves) and Phase II (35 circles at each of 5 yaws, 175 touches). An
agent's env step is one commanded touch, so a budget is a number of env steps.
"""

from __future__ import annotations

from dvrk_gym import paper

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

DEFAULT_EVAL_POINTS = 20
"""Evaluations along a learning curve unless asked otherwise (a training of fewer env steps has one a step)."""
MAX_EVAL_POINTS = 10_000
"""The most evaluations along a learning curve (``TrainConfig.eval_points``; a profile's ``rl_eval_points``)."""

PHASE1_MOVES = paper.PHASE1_TRAJECTORIES * paper.PHASE1_POSES_PER_TRAJECTORY
"""Commanded poses of the paper's Phase I: 57 trajectories x 93 (5,301)."""
PHASE2_TOUCHES = paper.PHASE2_TOUCHES
"""Touches of the paper's Phase II: 35 circles x 5 yaws (175)."""
CALIBRATOR_MOVES = PHASE1_MOVES + PHASE2_TOUCHES
"""Robot moves the two-phase calibrator uses (5,476)."""
BUDGETS: dict[str, int] = {"calibrator": CALIBRATOR_MOVES, "10x": 10 * CALIBRATOR_MOVES}
"""Named budgets in env steps: the calibrator's robot moves, and ten times that."""


def resolve_budget(budget: str | None = "calibrator", steps: int | None = None) -> int:
    """The number of env steps to train for.

    Args:
        budget: a name in :data:`BUDGETS`, or None when ``steps`` is given.
        steps: an explicit number of env steps; overrides ``budget``.

    Raises:
        ValueError: an unknown budget name, a non-positive ``steps``, or neither given.
    """
    if steps is not None:
        if isinstance(steps, bool) or int(steps) != steps or steps < 1:
            raise ValueError(f"steps must be a positive integer, got {steps!r}")
        return int(steps)
    if budget is None:
        raise ValueError(f"give a budget ({sorted(BUDGETS)}) or a number of steps")
    if budget not in BUDGETS:
        raise ValueError(f"unknown budget {budget!r}; valid: {sorted(BUDGETS)} (or an explicit number of steps)")
    return BUDGETS[budget]
