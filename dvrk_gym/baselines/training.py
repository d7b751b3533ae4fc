"""Train an agent for a budget of env steps, measuring how well it does as it learns.

Every training env step is one robot move of the budget: a commanded touch (GridTouch-v0)
or a pick (Debridement-v0). The learning curve evaluates the deterministic policy on a
separate env (same instrument) at evenly spaced points (:mod:`dvrk_gym.baselines.curves`
says how a point is measured). These evaluation moves are measurements and are not counted
in the budget.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv
from tqdm.auto import tqdm

from dvrk_gym import paper
from dvrk_gym.baselines.agents import AgentSpec, build_model, check_policy_kwargs, get_agent
from dvrk_gym.baselines.budgets import CALIBRATOR_MOVES, DEBRIDEMENT_ID, DEFAULT_EVAL_POINTS, GRID_TOUCH_ID, MAX_EVAL_POINTS
from dvrk_gym.baselines.curves import CURVE_TRIALS, CurveEvaluator, CurvePoint, evaluate_curve_point, evaluate_pick_curve_point
from dvrk_gym.baselines.resume import ResetRecorder, TrainingStateError, TrainingStateWriter, restore_training_state
from dvrk_gym.baselines.wrappers import TRAINING_YAWS, TourStart
from dvrk_gym.envs.grid_touch import N_CIRCLES
from dvrk_gym.utils.checks import check_choice, check_endoscope_resolution, check_float, check_int, check_int_fields
from dvrk_gym.utils.torch_threads import torch_threads

logger = logging.getLogger(__name__)

VEC_ENVS = ("dummy", "subproc")
SAVE_EVERY = 500
"""Env steps between two saves of a training's state (a GridTouch agent makes them in about
40 s, a pick agent in about 4 minutes, on this project's 2-core machine)."""


@dataclass(frozen=True)
class TrainConfig:
    """Settings of a training run.

    Attributes:
        agent: a name in :data:`dvrk_gym.baselines.agents.AGENTS`.
        steps: env steps (robot moves) to train for; see
            :func:`dvrk_gym.baselines.budgets.resolve_budget`.
        seed: seeds the model and the training envs (``reset(seed=...)`` via the vector
            env). Note stable-baselines3 also seeds Python's, numpy's and torch's global
            generators with it, and its HER buffer draws from numpy's; this package draws
            nothing from global generators.
        bias: the cable bias preset.
        bias_seed: which instrument.
        camera_resolution: endoscope image size (width, height), pixels; evaluate at the same.
        training_yaws: "paper" (a tour of the circles per paper yaw) or "random"
            (GridTouch agents; a pick's yaw comes from its fragment).
        n_envs: parallel training envs (each step of the vector env is ``n_envs`` moves).
        vec_env: "dummy" (one process) or "subproc" (a process per env).
        eval_points: evaluations along the learning curve (plus one before training); at
            most one per env step, so a shorter training has ``steps``.
        curve_trials: pick agents: debridement trials (of eight picks) per curve point.
        torch_threads: torch's intra-op threads while training (restored after). One is
            fastest here: small networks on 2 shared cores ran 12x slower with two threads.
        env_overrides: ``gym.make`` keywords replacing the agent's (``reward_type``...).
        overrides: hyperparameters replacing the agent's (``learning_starts``...).
    """

    agent: str = "sac_her"
    steps: int = CALIBRATOR_MOVES
    seed: int = 0
    bias: str = "paper"
    bias_seed: int = 0
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX
    training_yaws: str = "paper"
    n_envs: int = 1
    vec_env: str = "dummy"
    eval_points: int = DEFAULT_EVAL_POINTS
    curve_trials: int = CURVE_TRIALS
    torch_threads: int = 1
    env_overrides: dict[str, Any] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "camera_resolution", check_endoscope_resolution("camera_resolution", self.camera_resolution))
        if not isinstance(self.agent, str):
            raise ValueError(f"agent must be an agent's name, got {self.agent!r}")
        get_agent(self.agent)
        check_choice("training_yaws", self.training_yaws, TRAINING_YAWS)
        check_choice("vec_env", self.vec_env, VEC_ENVS)
        bounds = {
            "steps": (1, 10**9),
            "seed": (0, 2**31 - 1),
            "bias_seed": (0, 2**31 - 1),
            "n_envs": (1, 64),
            "eval_points": (1, MAX_EVAL_POINTS),
        }
        bounds.update({"curve_trials": (1, 10_000), "torch_threads": (1, 256)})
        check_int_fields("TrainConfig", self, bounds)
        for name in ("env_overrides", "overrides"):
            if not isinstance(getattr(self, name), dict):
                raise ValueError(f"{name} must be a dict of keywords, got {getattr(self, name)!r}")
        if "policy_kwargs" in self.overrides:  # what an agent file may hold: refused before training, not at its save
            check_policy_kwargs(self.overrides["policy_kwargs"])

    @property
    def spec(self) -> AgentSpec:
        return get_agent(self.agent)

    def env_kwargs(self) -> dict[str, Any]:
        """``gym.make`` keywords of the training and evaluation envs."""
        return {
            "bias": self.bias,
            "bias_seed": self.bias_seed,
            "camera_resolution": self.camera_resolution,
            **self.spec.env_kwargs,
            **self.env_overrides,
        }

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class TrainResult:
    """A trained model and how its training went.

    Attributes:
        model: the stable-baselines3 model.
        config: the run's settings.
        curve: the learning curve.
        env_steps: env steps trained (``steps`` rounded up to a multiple of ``n_envs``).
        train_seconds: wall time of training without the curve's evaluations, s.
        eval_seconds: wall time of the curve's evaluations, s.
    """

    model: BaseAlgorithm
    config: TrainConfig
    curve: list[CurvePoint]
    env_steps: int
    train_seconds: float
    eval_seconds: float

    @property
    def steps_per_second(self) -> float:
        """Training env steps per second of wall time (gradient updates included)."""
        return self.env_steps / max(self.train_seconds, 1e-9)


def make_agent_env(config: TrainConfig, training: bool) -> gym.Env:
    """One env as the agent sees it (training: the yaw schedule; evaluation: options choose)."""
    env = gym.make(config.spec.env_id, **config.env_kwargs())
    return config.spec.wrap(env, config.training_yaws if training else None)


def _training_env(config: TrainConfig, index: int) -> gym.Env:
    """Sub-env ``index`` of the training vector env: GridTouch-v0's begin their tours spread
    over the circles (:class:`~dvrk_gym.baselines.wrappers.TourStart`), not all at the first."""
    env = make_agent_env(config, training=True)
    if config.spec.env_id == GRID_TOUCH_ID and index:
        env = TourStart(env, start=index * N_CIRCLES // config.n_envs)
    return ResetRecorder(env)


def make_training_vec_env(config: TrainConfig) -> VecEnv:
    """The training vector env: ``n_envs`` copies, one process each with "subproc"; each
    env's resets recorded (:class:`~dvrk_gym.baselines.resume.ResetRecorder`), so that its
    state can be saved between episodes."""
    factories: list[Callable[[], gym.Env]] = [functools.partial(_training_env, config, index) for index in range(config.n_envs)]
    if config.vec_env == "subproc":
        return SubprocVecEnv(factories, start_method="forkserver")
    return DummyVecEnv(factories)


def curve_evaluator(config: TrainConfig) -> CurveEvaluator:
    """The learning-curve measurement of an agent's env: touch error, or debridement trials."""
    if config.spec.env_id == DEBRIDEMENT_ID:
        return lambda model, env, env_steps, seed: evaluate_pick_curve_point(model, env, env_steps, seed, n_trials=config.curve_trials)
    return evaluate_curve_point


class LearningCurve(BaseCallback):
    """Evaluate at evenly spaced env steps and show a progress bar.

    A point is measured at the first env step at or past its mark, before the gradient
    updates that step's rollout brings; the last one is measured again when the training
    ends if updates came after it, so it is the model the training returns (and saves).

    Args:
        env: the evaluation env (wrapped as the agent sees it).
        total_steps: the run's env steps.
        n_points: evaluations during training (after one at step 0).
        seed: seed of every evaluation (the same touches, or fragments, each time).
        progress: show a progress bar.
        evaluate: the measurement (default: GridTouch's touch error over the 35 circles).
    """

    def __init__(
        self, env: gym.Env, *, total_steps: int, n_points: int, seed: int, progress: bool, evaluate: CurveEvaluator = evaluate_curve_point
    ) -> None:
        super().__init__()
        self.eval_env = env
        self.measure = evaluate
        self.marks = list(np.unique(np.linspace(0, total_steps, n_points + 1).round().astype(int)))
        self.seed = seed
        self.points: list[CurvePoint] = []
        self.eval_seconds = 0.0
        self.resumed = False
        self._updates_measured: int | None = None  # the model's gradient updates when the last point was measured
        self._bar = tqdm(total=total_steps, desc="training", unit="step", disable=not progress)

    def record(self) -> dict[str, Any]:
        """The curve so far, JSON values, for a saved training state."""
        return {"points": [p.to_json() for p in self.points], "marks": [int(m) for m in self.marks], "eval_seconds": self.eval_seconds}

    def restore(self, record: Any, env_steps: int) -> None:
        """Take up a :meth:`record` saved at ``env_steps``; the training then goes on without
        evaluating again at its start.

        Raises:
            ValueError: ``record`` is not one :meth:`record` gives.
        """
        if not isinstance(record, dict) or set(record) != {"points", "marks", "eval_seconds"}:
            raise ValueError("a learning curve's record holds 'points', 'marks' and 'eval_seconds'")
        try:
            points = [CurvePoint.from_json(point) for point in record["points"]]
            marks = [check_int("a mark", mark, 0) for mark in record["marks"]]
            eval_seconds = check_float("eval_seconds", record["eval_seconds"], low=0.0)
        except (TypeError, ValueError) as error:
            raise ValueError(f"a learning curve's record is malformed ({error})") from None
        if not points or any(mark <= env_steps for mark in marks):
            raise ValueError(f"a learning curve's record at {env_steps} env steps must have points and only later marks")
        self.points, self.marks, self.eval_seconds, self.resumed = points, marks, eval_seconds, True
        self._bar.initial = self._bar.n = self._bar.last_print_n = env_steps  # the rate counts this run's steps only
        self._bar.refresh()

    def evaluate(self) -> None:
        """Measure the model now; a measure at the env step of the last point replaces it."""
        start = time.perf_counter()
        point = self.measure(self.model, self.eval_env, self.num_timesteps, self.seed)
        self.eval_seconds += time.perf_counter() - start
        if self.points and self.points[-1].env_steps == point.env_steps:
            self.points.pop()
        self.points.append(point)
        self._updates_measured = getattr(self.model, "_n_updates", None)  # stable-baselines3's count of gradient updates
        self.marks = [m for m in self.marks if m > self.num_timesteps]
        self._bar.set_postfix(mm=f"{point.mm_error:.2f}", success=f"{point.success_rate:.2f}")
        logger.info("%d env steps: %.2f mm, %.1f px, success %.2f", point.env_steps, point.mm_error, point.pixel_error, point.success_rate)

    def _on_training_start(self) -> None:
        if not self.resumed:
            self.evaluate()

    def _on_step(self) -> bool:
        self._bar.update(self.training_env.num_envs)
        if self.marks and self.num_timesteps >= self.marks[0]:
            self.evaluate()
        return True

    def _on_training_end(self) -> None:
        # The last mark is measured at the last env step, before the gradient updates that
        # follow it: measured again, the last point is the model the training returns.
        updates = getattr(self.model, "_n_updates", None)
        if not self.points or self.points[-1].env_steps != self.num_timesteps or updates is None or updates != self._updates_measured:
            self.evaluate()

    def close(self) -> None:
        """End the progress bar's line (:func:`_train` calls it when the training ends or is
        interrupted: what is printed next starts on a line of its own)."""
        self._bar.close()


def train(config: TrainConfig, *, progress: bool = True, state_path: str | Path | None = None, save_every: int = SAVE_EVERY) -> TrainResult:
    """Train ``config.agent`` for ``config.steps`` env steps, with its learning curve.

    Args:
        config: the run's settings.
        progress: show a progress bar.
        state_path: where to save the training's state every ``save_every`` env steps
            (between episodes; :mod:`dvrk_gym.baselines.resume`). If the file exists, the
            training resumes from it (it must be a state of the same settings, written by this
            version of dvrk_gym with the same libraries), and ends as a training never stopped
            would, bit for bit.
            The file is left in place: delete it once the model and whatever else the
            caller writes are saved. None: no saves.
        save_every: env steps between saves.

    Raises:
        TrainingStateError: ``state_path`` exists but cannot be resumed (the message says why).
    """
    with torch_threads(config.torch_threads):
        return _train(config, progress, None if state_path is None else Path(state_path), save_every)


def _train(config: TrainConfig, progress: bool, state_path: Path | None, save_every: int) -> TrainResult:
    train_env = make_training_vec_env(config)  # seeded by the model (env i: seed + i)
    eval_env = make_agent_env(config, training=False)
    curve: LearningCurve | None = None
    try:
        model = build_model(config.spec, train_env, seed=config.seed, overrides=config.overrides)
        curve = LearningCurve(
            eval_env,
            total_steps=config.steps,
            n_points=config.eval_points,
            seed=config.seed + 10_000,
            progress=progress,
            evaluate=curve_evaluator(config),
        )
        wall_before = _resume(state_path, model, curve, config) if state_path is not None and state_path.exists() else 0.0
        callbacks: list[BaseCallback] = [curve]
        start = time.perf_counter()
        if state_path is not None:
            record = lambda: {"curve": curve.record(), "wall_seconds": wall_before + time.perf_counter() - start}  # noqa: E731
            callbacks.append(TrainingStateWriter(state_path, save_every, config.to_dict(), record))
        resumed = model.num_timesteps > 0
        model.learn(total_timesteps=config.steps - model.num_timesteps, callback=CallbackList(callbacks), reset_num_timesteps=not resumed)
        wall = wall_before + time.perf_counter() - start
    finally:
        if curve is not None:
            curve.close()
        train_env.close()
        eval_env.close()
    result = TrainResult(model, config, curve.points, int(model.num_timesteps), wall - curve.eval_seconds, curve.eval_seconds)
    logger.info("%s: %d env steps in %.0f s (%.1f steps/s)", config.agent, result.env_steps, result.train_seconds, result.steps_per_second)
    return result


def _resume(state_path: Path, model: BaseAlgorithm, curve: LearningCurve, config: TrainConfig) -> float:
    """Restore the training state at ``state_path`` into ``model`` and ``curve``; the wall time (s) trained before."""
    record = restore_training_state(state_path, model, config.to_dict())
    try:
        if not 0 < model.num_timesteps < config.steps:
            raise ValueError(f"it was saved at {model.num_timesteps} env steps, outside the run's (0, {config.steps})")
        curve.restore(record.get("curve"), model.num_timesteps)
        wall_seconds = check_float("wall_seconds", record["wall_seconds"], low=0.0)
    except (KeyError, TypeError, ValueError) as error:
        raise TrainingStateError(f"{state_path}: not a training state these settings can resume ({error})") from None
    logger.info("resuming %s at %d of %d env steps from %s", config.agent, model.num_timesteps, config.steps, state_path)
    return wall_seconds
