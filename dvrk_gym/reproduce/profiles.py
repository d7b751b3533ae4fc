"""How much of the paper a reproduction runs: the full run, the quick one, or a custom one."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import AGENT_ENVS, GRID_TOUCH_ID

SEARCHES = ("paper", "quick")


@dataclass(frozen=True)
class Profile:
    """The budgets of a reproduction.

    Attributes:
        name: shown in the report.
        n_trajectories: Phase I trajectories (the paper: 57).
        steps_per_trajectory: commanded poses per trajectory (the paper: about 92).
        dnn_epochs: DNN training epochs (the paper: 1000).
        search: "paper" (the 30 models of the paper's search: 10-fold CV, the 23 sweep
            nets on 3 folds) or "quick" (five models, 30 epochs, 3 folds).
        debridement_trials: trials of each debridement cell (the paper: 15).
        debridement_picks: picks per trial (the paper: 8).
        rl_agents: the RL agents trained on GridTouch-v0 (names in
            :data:`dvrk_gym.baselines.agents.AGENTS`).
        rl_steps: their training budget in robot moves; None: the calibrator's
            (Phase I poses + 175 Phase II touches, :data:`~dvrk_gym.baselines.budgets.CALIBRATOR_MOVES`).
        rl_eval_points: evaluations along each learning curve.
        camera_resolution: endoscope image size (width, height), pixels.
    """

    name: str
    n_trajectories: int = paper.PHASE1_TRAJECTORIES
    steps_per_trajectory: int = paper.PHASE1_POSES_PER_TRAJECTORY
    dnn_epochs: int = paper.DNN_EPOCHS
    search: str = "paper"
    debridement_trials: int = paper.DEBRIDEMENT_TRIALS
    debridement_picks: int = paper.FRAGMENTS_PER_TRIAL
    rl_agents: tuple[str, ...] = ("sac_her", "sac")
    rl_steps: int | None = None
    rl_eval_points: int = 20
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX

    def __post_init__(self) -> None:
        object.__setattr__(self, "camera_resolution", tuple(int(v) for v in self.camera_resolution))
        object.__setattr__(self, "rl_agents", tuple(self.rl_agents))
        if self.search not in SEARCHES:
            raise ValueError(f"search must be one of {SEARCHES}, got {self.search!r}")
        for name in ("n_trajectories", "steps_per_trajectory", "dnn_epochs", "debridement_trials", "debridement_picks", "rl_eval_points"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        grid_agents = sorted(name for name, env_id in AGENT_ENVS.items() if env_id == GRID_TOUCH_ID)
        unknown = [agent for agent in self.rl_agents if agent not in grid_agents]
        if unknown:
            raise ValueError(f"rl_agents must be GridTouch-v0 agents {grid_agents}, got {unknown}")
        if self.rl_steps is not None and self.rl_steps < 1:
            raise ValueError(f"rl_steps must be >= 1 or None, got {self.rl_steps}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


FULL = Profile(name="full")
"""The paper's budgets: 57 Phase I trajectories, the whole model search, 15 trials per
debridement cell, SAC+HER and SAC for the calibrator's number of robot moves."""
QUICK = Profile(name="quick", search="quick", debridement_trials=3, rl_agents=("sac_her",), rl_steps=1000, rl_eval_points=5)
"""The paper's calibration budgets (the data decide the calibrators' accuracy), a five-model
search, 3 trials per debridement cell and 1,000 moves of SAC+HER: a few minutes."""
PROFILES = {"full": FULL, "quick": QUICK}
