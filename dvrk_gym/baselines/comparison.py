"""The agents on the calibrators' benchmarks, and tables of results against robot moves.

Touch grid (GridTouch agents): an agent touches the 35 circles at the six yaw settings
through the same :func:`~dvrk_gym.calibration.benchmark.touch_grid` and seeds as the
calibrators in :func:`~dvrk_gym.calibration.pipeline.run_calibration`, so their rows are
comparable; an agent's commands are sent as they are, the calibrators' by the table's
protocol (the paper's lifts the rigid body's, :mod:`dvrk_gym.evaluation.table_protocol`; the
protocol is in each calibrator row's source). The calibrators' rows come from a calibration
run folder (``calibration_table.json`` and ``pipeline_config.json``, as ``dvrk-gym evaluate``
writes them).

Debridement (any agent, through :func:`~dvrk_gym.baselines.transfer.pick_policy`): the
paper's trials of eight picks on Debridement-v0, run by
:func:`~dvrk_gym.evaluation.trials.run_debridement` with the same seeds for the agents and
for the calibrators (loaded from the calibration run folder by
:func:`~dvrk_gym.calibration.loading.load_calibrator` and aimed by
``CalibratedPolicy(calibrator, target=fragment_target)``, as ``dvrk-gym debride`` does):
success, outcomes A/B/C and time per fragment.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dvrk_gym import paper
from dvrk_gym.baselines.budgets import DEBRIDEMENT_ID, GRID_TOUCH_ID, PHASE2_TOUCHES
from dvrk_gym.baselines.checkpoints import LoadedAgent
from dvrk_gym.baselines.training import TrainConfig, make_agent_env
from dvrk_gym.baselines.transfer import pick_policy
from dvrk_gym.calibration.benchmark import YAW_SETTINGS, CircleErrors, touch_grid
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.pipeline import BENCHMARK_SEED_OFFSET, CALIBRATOR_FILES, SETTINGS_STAMP, PipelineConfig, read_pipeline_settings
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.evaluation.trials import Trial, run_debridement, totals
from dvrk_gym.sim.table.contact import DEFAULT_CONTACT
from dvrk_gym.utils.atomic import read_json
from dvrk_gym.utils.checks import check_endoscope_resolution, check_float
from dvrk_gym.utils.run_folder import check_made_here
from dvrk_gym.utils.source_fingerprint import source_fingerprint

logger = logging.getLogger(__name__)

BENCHMARK_SEED = BENCHMARK_SEED_OFFSET
"""The seed the calibration pipeline's benchmark uses (its config seed 0 + 1000)."""
CALIBRATORS = tuple(paper.METHOD_LABELS)
"""The calibrators of a calibration run folder, as ``dvrk-gym debride --calibrator`` names them."""
DEBRIDEMENT_TRIALS = paper.DEBRIDEMENT_TRIALS
"""Trials of eight picks per method (the paper's)."""


@dataclass(frozen=True)
class ComparisonRow:
    """One method in the comparison.

    Attributes:
        method: its name.
        robot_moves: robot moves used to build it (Phase I poses + Phase II touches, or
            training env steps).
        mm_error: mean touch error over the 35 circles x 6 settings, millimetres.
        pixel_error: the same in the left image, pixels.
        source: where the numbers come from.
    """

    method: str
    robot_moves: int
    mm_error: float
    pixel_error: float
    source: str


def benchmark_agent(agent: LoadedAgent, seed: int = BENCHMARK_SEED, *, progress: bool = False) -> dict[str, CircleErrors]:
    """The agent's errors at each of the six yaw settings (``table[setting]``).

    Raises:
        ValueError: the agent learnt another env than GridTouch-v0 (the grid benchmark is its).
    """
    if agent.config.spec.env_id != GRID_TOUCH_ID:
        raise ValueError(f"{agent.label} learnt {agent.config.spec.env_id}; the calibrators' benchmark needs an agent of {GRID_TOUCH_ID}")
    env = make_agent_env(agent.config, training=False)
    try:
        return {label: touch_grid(env, agent.model, yaw, seed=seed + k, progress=progress) for k, (label, yaw) in enumerate(YAW_SETTINGS)}
    finally:
        env.close()


def agent_row(agent: LoadedAgent, settings: dict[str, CircleErrors]) -> ComparisonRow:
    """The comparison row of a benchmarked agent (``settings``: :func:`benchmark_agent`'s table).

    Raises:
        ValueError: an empty table.
    """
    if not settings:
        raise ValueError(f"{agent.label}: no benchmark settings to make a row of")
    mm = np.concatenate([e.mm for e in settings.values()])
    pixel = np.concatenate([e.pixel for e in settings.values()])
    return ComparisonRow(agent.label, agent.env_steps, float(np.mean(mm)), float(np.mean(pixel)), str(agent.path))


def calibration_rows(folder: Path) -> tuple[list[ComparisonRow], PipelineConfig]:
    """The calibrators' rows from a calibration run folder, with the run's settings.

    Robot moves: RBT and DNN use the Phase I poses (trajectories x poses per trajectory);
    DNN+RF adds the 175 Phase II touches.

    Raises:
        FileNotFoundError: the folder has no ``calibration_table.json``.
        ValueError: a file, not a folder; made by another dvrk_gym (its numbers are another
            simulator's); or the table is not one ``dvrk-gym evaluate`` writes (damaged or
            edited; the message names it).
    """
    folder = Path(folder)
    table_path = folder / "calibration_table.json"
    if folder.is_file():
        raise ValueError(f"{folder} is a file; --calibration takes a calibration run folder")
    if not table_path.exists():
        raise FileNotFoundError(f"{table_path} not found: run 'dvrk-gym evaluate --out {folder}' first")
    check_made_here(folder, SETTINGS_STAMP, remedy=CALIBRATE_AGAIN)
    table = read_json(table_path)
    config = _pipeline_config(folder)
    moves = calibrator_moves(config)
    rows = []
    try:
        protocol = table.get("protocol") or "raw"  # a table written before the protocol was recorded sent its predictions raw
        for method, stats in table["summary"].items():
            every = stats["all settings"]
            mm = check_float(f"{method}'s mean error (mm)", every["mm"]["mean"], low=0.0)
            px = check_float(f"{method}'s mean error (px)", every["pixel"]["mean"], low=0.0)
            rows.append(ComparisonRow(str(method), moves.get(method, -1), mm, px, f"{table_path} (protocol {protocol})"))
    except (KeyError, TypeError, AttributeError, ValueError) as error:
        raise ValueError(f"{table_path} is not a calibration table 'dvrk-gym evaluate' writes ({type(error).__name__}: {error})") from None
    return rows, config


def calibrator_moves(config: PipelineConfig) -> dict[str, int]:
    """Robot moves each calibrator of a run used: Phase I poses; DNN+RF adds the Phase II touches."""
    phase1 = config.n_trajectories * config.steps_per_trajectory
    return {"RBT": phase1, "DNN": phase1, "DNN+RF": phase1 + PHASE2_TOUCHES}


def _pipeline_config(folder: Path) -> PipelineConfig:
    settings = read_pipeline_settings(folder)
    if settings is None:
        logger.warning("%s has no settings: assuming the paper's budgets and default settings", folder)
        return PipelineConfig()
    return PipelineConfig.from_settings(settings, source=f"the settings of {folder}")


def agent_contact(config: TrainConfig) -> str:
    """The paper an agent learnt on: its env's ``contact`` ("compliant" or "rigid"; the env's
    default unless its settings replaced it). Its debridement picks meet the same paper."""
    return str(config.env_kwargs().get("contact", DEFAULT_CONTACT))


PICKS_CARRY = ("contact", "bias_config", "env")
"""What of a GridTouch agent's training env its transferred picks meet (keys of
:attr:`LoadedAgent.env_changes`): the paper and the instrument; GridTouch's own keywords
(the touch's approach, the reward) have no part in a pick."""
PROTOCOL_KEYWORDS = ("fragment", "max_picks", "action_mode")
"""Debridement-v0 keywords the paper's trial protocol sets, whatever the agent learnt on."""


def pick_env_kwargs(config: TrainConfig) -> dict[str, Any]:
    """The Debridement-v0 keywords of an agent's picks beyond its instrument, its paper
    (:func:`agent_contact`) and the protocol's: for a pick agent, every other keyword of its
    training env (the values :func:`~dvrk_gym.baselines.checkpoints.load_agent` restored
    included); for a GridTouch agent, none."""
    if config.spec.env_id != DEBRIDEMENT_ID:
        return {}
    own = ("bias", "bias_seed", "camera_resolution", "contact", *PROTOCOL_KEYWORDS)
    return {key: value for key, value in config.env_kwargs().items() if key not in own}


def env_change_notes(agent: LoadedAgent, picks: bool = False) -> list[str]:
    """How this version's env differs from the one ``agent`` learnt in (:attr:`LoadedAgent.env_changes`),
    one line each; with ``picks``, for a GridTouch agent only what its picks meet (:data:`PICKS_CARRY`);
    then :func:`source_notes`."""
    changes = agent.env_changes
    if picks and agent.config.spec.env_id == GRID_TOUCH_ID:
        changes = {key: line for key, line in changes.items() if key in PICKS_CARRY}
    return [f"{agent.label}: {line}" for line in changes.values()] + source_notes(agent)


def source_notes(agent: LoadedAgent) -> list[str]:
    """A line if ``agent`` was trained by other dvrk_gym source than this process runs (its
    recorded env settings may agree while the simulator's code differs), else none."""
    here = source_fingerprint()
    if agent.source == here:
        return []
    trained = "a dvrk_gym that did not record its source" if agent.source is None else agent.source.short()
    return [f"{agent.label}: trained by {trained}; evaluated with {here.short()}"]


def setting_mismatches(agent: LoadedAgent, calibration: PipelineConfig, picks: bool = False) -> list[str]:
    """Differences between an agent's world and a calibration run's that make rows incomparable,
    on the touch grid or (``picks``) in debridement, and the env changes of :func:`env_change_notes`."""
    notes = env_change_notes(agent, picks)
    for name in ("bias", "bias_seed", "camera_resolution"):
        mine, theirs = getattr(agent.config, name), getattr(calibration, name)
        if mine != theirs:
            notes.append(f"{agent.label}: {name} {mine!r}, but the calibration run used {theirs!r}")
    contact = agent_contact(agent.config)
    if contact != DEFAULT_CONTACT:
        moves = "picks" if picks else "touches"
        theirs = f"the calibrators' {moves} met the {DEFAULT_CONTACT} one"
        notes.append(f"{agent.label}: learnt on the {contact} paper and {moves} on it; {theirs}")
    return notes


def _moves(robot_moves: int) -> str:
    return f"{robot_moves:,}" if robot_moves >= 0 else "?"


def _text_table(title: str, header: str, lines: Sequence[str], notes: Sequence[str]) -> str:
    return "\n".join([title, header, *lines, *(f"note: {note}" for note in notes)])


def format_comparison(rows: list[ComparisonRow], notes: Sequence[str] = ()) -> str:
    """Method, robot moves, mean mm and pixel error over the 35 circles x 6 settings."""
    return _text_table(
        "Touch error over the 35 circles x 6 yaw settings, for the robot moves each method used",
        f"{'method':<32}{'robot moves':>12}{'mean mm':>10}{'mean px':>10}",
        [f"{row.method:<32}{_moves(row.robot_moves):>12}{row.mm_error:>10.2f}{row.pixel_error:>10.1f}" for row in rows],
        notes,
    )


@dataclass(frozen=True)
class DebridementRow:
    """One method's debridement trials.

    Attributes:
        method: its name.
        robot_moves: robot moves used to build it (see :class:`ComparisonRow`).
        picks: picks judged.
        success: picks that delivered their fragment.
        missed: outcome A (the jaws landed too far off).
        slipped: outcome B (well placed, the fragment slipped).
        pierced: outcome C (a raisin came up on one tip).
        time_per_fragment_s: mean simulated seconds per pick.
        source: where the method comes from.
    """

    method: str
    robot_moves: int
    picks: int
    success: int
    missed: int
    slipped: int
    pierced: int
    time_per_fragment_s: float
    source: str

    @property
    def success_rate(self) -> float:
        return self.success / self.picks if self.picks else float("nan")


def debridement_row(method: str, robot_moves: int, trials: Sequence[Trial], source: str) -> DebridementRow:
    """The row of a list of :class:`~dvrk_gym.evaluation.trials.Trial`."""
    total = totals(list(trials))
    return DebridementRow(
        method, robot_moves, total["picks"], total["success"], total["A"], total["B"], total["C"], total["time_per_fragment_s"], source
    )


def benchmark_debridement(
    agent: LoadedAgent, n_trials: int = DEBRIDEMENT_TRIALS, seed: int = 0, fragment: str = "pumpkin_seed", *, progress: bool = False
) -> list[Trial]:
    """The agent's debridement trials (GridTouch agents transferred by :func:`pick_policy`), in its
    world: its instrument, the paper it learnt on (:func:`agent_contact`), and a pick agent's
    other training keywords (:func:`pick_env_kwargs`)."""
    config = agent.config
    return run_debridement(
        pick_policy(agent),
        n_trials=n_trials,
        seed=seed,
        fragment=fragment,
        bias=config.bias,
        bias_seed=config.bias_seed,
        camera_resolution=config.camera_resolution,
        contact=agent_contact(config),
        env_kwargs=pick_env_kwargs(config),
        progress=progress,
    )


CALIBRATE_AGAIN = "calibrate again with this version: dvrk-gym calibrate --out NEW_FOLDER && dvrk-gym evaluate --out NEW_FOLDER"
"""What a comparison with a calibration folder of another dvrk_gym tells the user to do."""


def check_calibration_folder(folder: Path, *, table: bool, models: bool) -> None:
    """Refuse, before any benchmark runs, a calibration folder a comparison would refuse halfway
    (after the touch grid's files were written): its table (``table``) and every calibrator's
    model file (``models``) are read as :func:`calibration_rows` and
    :func:`calibration_debridement_rows` read them.

    Raises:
        FileNotFoundError, ValueError, ModelFileError: as those two raise.
    """
    if table:
        calibration_rows(folder)
    if models:
        for name in CALIBRATORS:
            load_calibrator(folder, name)


def calibration_debridement_rows(
    folder: Path,
    *,
    n_trials: int = DEBRIDEMENT_TRIALS,
    seed: int = 0,
    fragment: str = "pumpkin_seed",
    camera_resolution: tuple[int, int] | None = None,
    calibrators: Sequence[str] = CALIBRATORS,
    progress: bool = False,
) -> tuple[list[DebridementRow], PipelineConfig]:
    """The calibrators' debridement rows, run here as ``dvrk-gym debride`` runs them.

    Args:
        folder: a calibration run folder holding the calibrators' model files.
        n_trials, seed, fragment: the trials (use the agents' seed for comparable fragments).
        camera_resolution: the endoscope's image size (default: the calibration run's).
        calibrators: which of :data:`CALIBRATORS`.

    Raises:
        ValueError: no calibrators, a string instead of a list, or an unknown name.
        FileNotFoundError: the folder lacks a calibrator's model file.
    """
    folder = Path(folder)
    if isinstance(calibrators, str) or not calibrators:  # "rbt" would be the letters r, b, t
        raise ValueError(f"calibrators must be a list of some of {list(CALIBRATORS)}, got {calibrators!r}")
    unknown = sorted(set(calibrators) - set(CALIBRATORS))
    if unknown:
        raise ValueError(f"unknown calibrator(s) {unknown}; valid: {list(CALIBRATORS)}")
    config = _pipeline_config(folder)
    moves = calibrator_moves(config)
    resolution = check_endoscope_resolution("camera_resolution", camera_resolution or config.camera_resolution)
    rows = []
    for name in calibrators:
        path = folder / CALIBRATOR_FILES[name]
        if not path.exists():
            raise FileNotFoundError(f"{path} not found: run 'dvrk-gym calibrate --out {folder}' first")
        calibrator, _ = load_calibrator(folder, name)
        policy = CalibratedPolicy(calibrator, target=fragment_target)
        trials = run_debridement(
            policy,
            n_trials=n_trials,
            seed=seed,
            fragment=fragment,
            bias=config.bias,
            bias_seed=config.bias_seed,
            camera_resolution=resolution,
            progress=progress,
        )
        label = paper.METHOD_LABELS[name]
        rows.append(debridement_row(label, moves[label], trials, str(path)))
    return rows, config


def format_debridement_comparison(rows: Sequence[DebridementRow], notes: Sequence[str] = ()) -> str:
    """Method, robot moves, success, A/B/C and time per fragment, one row each."""
    lines = []
    for row in rows:
        success = f"{row.success}/{row.picks} {100 * row.success_rate:.0f}%" if row.picks else "0/0"
        lines.append(
            f"{row.method:<48}{_moves(row.robot_moves):>12}{success:>15}{row.missed:>5}{row.slipped:>5}{row.pierced:>5}{row.time_per_fragment_s:>12.2f}"
        )
    return _text_table(
        "Debridement (trials of 8 picks): success and time per fragment, for the robot moves each method used",
        f"{'method':<48}{'robot moves':>12}{'success':>15}{'A':>5}{'B':>5}{'C':>5}{'s/fragment':>12}",
        lines,
        notes,
    )
