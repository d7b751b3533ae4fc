"""How much of the paper a reproduction runs: the full run, the quick one, or a custom one."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import Any

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import AGENT_ENVS, GRID_TOUCH_ID, MAX_EVAL_POINTS
from dvrk_gym.calibration.phase1 import MAX_STEPS_PER_TRAJECTORY, MAX_TRAJECTORIES
from dvrk_gym.envs.debridement_config import MAX_PICKS
from dvrk_gym.utils.atomic import read_json
from dvrk_gym.utils.checks import check_choice, check_endoscope_resolution, check_file_stem, check_int

SEARCHES = ("paper", "quick")
_MAX_COUNT = 10**7
"""An upper bound on every count of a profile (trajectories, epochs, trials, steps...)."""

MAX_PROFILE_BYTES = 2**20
"""The largest profile file read, bytes (a profile is a few lines of JSON)."""


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
        check_file_stem("name", self.name)  # it names the run folder, dvrk_gym_out/reproduce-<name>
        object.__setattr__(self, "camera_resolution", check_endoscope_resolution("camera_resolution", self.camera_resolution))
        if isinstance(self.rl_agents, str) or not isinstance(self.rl_agents, (list, tuple)):
            raise ValueError(f"rl_agents must be a list of agent names, got {self.rl_agents!r}")
        object.__setattr__(self, "rl_agents", tuple(self.rl_agents))
        if not all(isinstance(agent, str) for agent in self.rl_agents):
            raise ValueError(f"rl_agents must be a list of agent names, got {list(self.rl_agents)!r}")
        check_choice("search", self.search, SEARCHES)
        check_int("n_trajectories", self.n_trajectories, 1, MAX_TRAJECTORIES)  # the calibration's own bounds
        check_int("steps_per_trajectory", self.steps_per_trajectory, 1, MAX_STEPS_PER_TRAJECTORY)
        for name in ("dnn_epochs", "debridement_trials"):
            check_int(name, getattr(self, name), 1, _MAX_COUNT)
        # The bounds of the envs and trainings they go to, checked here: a run folder is
        # stamped with its profile, so a value refused only when its task ran would leave a
        # folder that the corrected profile cannot resume.
        check_int("debridement_picks", self.debridement_picks, 1, MAX_PICKS)
        check_int("rl_eval_points", self.rl_eval_points, 1, MAX_EVAL_POINTS)
        if len(set(self.rl_agents)) != len(self.rl_agents):
            raise ValueError(f"rl_agents repeats an agent: {list(self.rl_agents)}; give each once")
        grid_agents = sorted(name for name, env_id in AGENT_ENVS.items() if env_id == GRID_TOUCH_ID)
        unknown = [agent for agent in self.rl_agents if agent not in grid_agents]
        if unknown:
            raise ValueError(f"rl_agents must be GridTouch-v0 agents {grid_agents}, got {unknown}")
        if self.rl_steps is not None:
            check_int("rl_steps (or None)", self.rl_steps, 1, _MAX_COUNT)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values: Any) -> Profile:
        """A profile from its fields as JSON gives them (lists for tuples).

        Raises:
            ValueError: not an object, an unknown field (named), or a bad value.
        """
        if not isinstance(values, dict):
            raise ValueError(f"a profile must be a JSON object of Profile fields, got {type(values).__name__}")
        known = {field.name for field in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown profile field(s) {unknown}; the fields are {sorted(known)}")
        if "name" not in values:
            raise ValueError("a profile needs a 'name'")
        return cls(**values)

    @classmethod
    def from_file(cls, path: str | os.PathLike) -> Profile:
        """A profile from a JSON file of its fields (see :meth:`from_dict`); errors name the file."""
        try:
            return cls.from_dict(read_json(path, max_bytes=MAX_PROFILE_BYTES))
        except ValueError as error:
            raise ValueError(f"profile {path}: {error}") from None


FULL = Profile(name="full")
"""The paper's budgets: 57 Phase I trajectories, the whole model search, 15 trials per
debridement cell, SAC+HER and SAC for the calibrator's number of robot moves."""
QUICK = Profile(name="quick", search="quick", debridement_trials=3, rl_agents=("sac_her",), rl_steps=1000, rl_eval_points=5)
"""The paper's calibration budgets (the data decide the calibrators' accuracy), a five-model
search, 3 trials per debridement cell and 1,000 moves of SAC+HER: a few minutes."""
TINY = Profile(
    name="tiny",
    n_trajectories=2,
    steps_per_trajectory=30,
    dnn_epochs=20,
    search="quick",
    debridement_trials=1,
    debridement_picks=2,
    rl_agents=("sac",),
    rl_steps=60,
    rl_eval_points=1,
    camera_resolution=(480, 270),
)
"""Every stage at its smallest (2 trajectories, 20 epochs, 1 trial of 2 picks per cell, 60 RL
moves, 480 x 270): about a minute on 2 cores. Its numbers mean nothing; it is for the tests
and the fault-injection benchmark (``dvrk-gym reproduce --profile`` takes its JSON)."""
PROFILES = {"full": FULL, "quick": QUICK}
