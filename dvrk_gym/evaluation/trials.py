"""The paper's debridement trial table, for any policy.

Each trial is one Debridement-v0 episode of eight picks (primitive mode), run through
:func:`dvrk_gym.evaluation.episodes.run_episodes`, so a calibrator (through
:class:`~dvrk_gym.calibration.policy.CalibratedPolicy`), a trained agent or any callable is
judged the same way. A table is a list of :class:`Trial` (one row per trial: the outcome of
each pick, seconds per fragment, seconds per phase); :func:`totals` sums it up;
:func:`format_trial_table` prints it beside the paper's figures; :func:`save_cell` writes
it as JSON (and text) with a picture of the outcome grid.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from dvrk_gym import paper
from dvrk_gym.envs.debridement import DebridementEnv
from dvrk_gym.envs.picks import PHASES
from dvrk_gym.evaluation.episodes import run_episodes
from dvrk_gym.sim.table.contact import DEFAULT_CONTACT
from dvrk_gym.sim.table.judge import outcome_counts
from dvrk_gym.utils.atomic import atomic_savefig, atomic_write_json, atomic_write_text
from dvrk_gym.utils.checks import check_int

OUTCOME_COLOURS = {"-": "#4caf50", "A": "#e53935", "B": "#fb8c00", "C": "#8e24aa", "": "#bdbdbd"}
"""Colour of each outcome in the outcome grid ("" marks no pick)."""
OUTCOME_NAMES = {"-": "success", "A": "A: missed", "B": "B: slipped", "C": "C: one tip", "": "no pick"}
"""The outcome grid's legend."""


@dataclass(frozen=True)
class Trial:
    """One debridement trial.

    Attributes:
        outcomes: the outcome of each pick, in pick order ("-", "A", "B" or "C").
        time_per_fragment_s: simulated seconds per pick.
        phase_s: mean seconds of each phase (to seed ... drop and rotate).
        sim_error: what went wrong in the physics, or None.
        unpicked_delivered: fragments no pick went for that ended in the receptacle (carried
            there with another).
        unpicked_lost: fragments no pick went for that left the paper otherwise (taken off the
            jaws with another, or moved off the paper by another's pick); they have no
            outcome, so the trial has fewer picks than fragments.
    """

    outcomes: list[str]
    time_per_fragment_s: float
    phase_s: dict[str, float]
    sim_error: str | None = None
    unpicked_delivered: int = 0
    unpicked_lost: int = 0


def cell_name(method: str, fragment: str) -> str:
    """File stem of one cell of the debridement table: ``debridement_dnn_rf_raisin``."""
    return f"debridement_{method.replace('+', '_')}_{fragment}"


def cell_label(method: str, fragment: str) -> str:
    """A cell in words: ``"DNN+RF, pumpkin seeds"`` (names the paper does not use are kept)."""
    return f"{paper.METHOD_LABELS.get(method, method)}, {paper.FRAGMENT_LABELS.get(fragment, fragment)}"


def run_trials(env: gym.Env, policy: Any, n_trials: int, seed: int = 0, *, progress: bool = True) -> list[Trial]:
    """Run ``n_trials`` debridement episodes of ``policy`` (any policy) and collect the table.

    Args:
        env: a Debridement-v0 environment in primitive mode.
        policy: anything :func:`dvrk_gym.evaluation.episodes.run_episodes` accepts.
        n_trials: how many trials (episodes).
        seed: the first trial's reset seed; the rest continue its stream.
        progress: show a progress bar.
    """
    base = env.unwrapped
    if not isinstance(base, DebridementEnv) or base.config.action_mode != "primitive":
        mode = f" in {base.config.action_mode!r} mode" if isinstance(base, DebridementEnv) else ""
        raise ValueError(f"debridement trials need a Debridement-v0 env in primitive mode, got {type(base).__name__}{mode}")
    check_int("n_trials", n_trials, 1, 10**6)
    results = run_episodes(env, policy, n_episodes=n_trials, seed=seed, progress=progress, description="debridement trials")
    trials = []
    for result in results:
        info = result.final_info
        outcomes = [o for o in str(info.get("outcomes", "")).split(",") if o]
        phases = {name: float(info.get(f"time_{name}_s", float("nan"))) for name in PHASES}
        trials.append(
            Trial(
                outcomes,
                float(info.get("time_per_fragment", float("nan"))),
                phases,
                info.get("sim_error"),
                int(info.get("unpicked_delivered", 0)),
                int(info.get("unpicked_lost", 0)),
            )
        )
    return trials


def run_debridement(
    policy: Any,
    *,
    n_trials: int,
    seed: int,
    fragment: str = "pumpkin_seed",
    bias: str = "paper",
    bias_seed: int = 0,
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX,
    max_picks: int | None = None,
    progress: bool = False,
    contact: str = DEFAULT_CONTACT,
    env_kwargs: Mapping[str, Any] | None = None,
) -> list[Trial]:
    """``n_trials`` debridement trials of ``policy`` on a fresh Debridement-v0 (primitive mode), closed after.

    Args:
        policy: anything :func:`run_trials` accepts.
        n_trials: how many trials.
        seed: the first trial's reset seed.
        fragment: what to pick ("pumpkin_seed" or "raisin").
        bias: the cable bias preset.
        bias_seed: which instrument.
        camera_resolution: the endoscope's image size (width, height), pixels.
        max_picks: picks per trial (None: the env's, the paper's eight).
        progress: show a progress bar.
        contact: the paper under the picks, Debridement-v0's ``contact`` ("compliant" or "rigid").
        env_kwargs: other Debridement-v0 keywords (``timing``, ``gripper``...), None: its defaults.
    """
    settings: dict[str, Any] = {
        "fragment": fragment,
        "bias": bias,
        "bias_seed": bias_seed,
        "camera_resolution": tuple(camera_resolution),
        "contact": contact,
    }
    if max_picks is not None:
        settings["max_picks"] = max_picks
    clashing = sorted(set(settings) & set(env_kwargs or {}))
    if clashing:
        raise ValueError(f"env_kwargs must not repeat run_debridement's own arguments: {clashing}")
    settings.update(env_kwargs or {})
    env = gym.make("dvrk_gym/Debridement-v0", **settings)
    try:
        return run_trials(env, policy, n_trials, seed=seed, progress=progress)
    finally:
        env.close()


def _weighted_mean(values: list[float], weights: np.ndarray) -> float:
    """Mean over the trials that picked something, weighted by their picks."""
    timed = weights > 0
    return float(np.average(np.array(values)[timed], weights=weights[timed])) if timed.any() else float("nan")


def totals(trials: list[Trial]) -> dict[str, Any]:
    """Counts over all trials: picks, success, A, B, C, the fragments no pick went for
    (``unpicked_delivered``, ``unpicked_lost``); mean time per fragment and phases (s)."""
    every = [o for t in trials for o in t.outcomes]
    weights = np.array([len(t.outcomes) for t in trials], dtype=float)
    phases = {name: _weighted_mean([t.phase_s[name] for t in trials], weights) for name in (trials[0].phase_s if trials else {})}
    return {
        "picks": len(every),
        **outcome_counts(every),
        "time_per_fragment_s": _weighted_mean([t.time_per_fragment_s for t in trials], weights),
        "phase_s": phases,
        "sim_errors": sum(t.sim_error is not None for t in trials),
        "unpicked_delivered": sum(t.unpicked_delivered for t in trials),
        "unpicked_lost": sum(t.unpicked_lost for t in trials),
    }


def unpicked_note(total: Mapping[str, Any]) -> str:
    """What became of the fragments no pick went for, in words (empty when there were none):
    "1 fragment lost with another's pick, not counted in the picks"."""
    parts = []
    for key, what in (("unpicked_lost", "lost with another's pick"), ("unpicked_delivered", "delivered with another's pick")):
        count = int(total.get(key, 0))
        if count:
            parts.append(f"{count} fragment{'s' if count > 1 else ''} {what}")
    return f"{' and '.join(parts)}, not counted in the picks" if parts else ""


def format_trial_table(trials: list[Trial], calibrator: str, fragment: str, seed: int = 0) -> str:
    """The paper's trial table in text: one row per trial, totals, the paper's figures beside."""
    label = paper.METHOD_LABELS.get(calibrator, calibrator)
    count = f"{len(trials)} trial" + ("" if len(trials) == 1 else "s")
    lines = [f"Debridement of {paper.FRAGMENT_LABELS.get(fragment, fragment)} with {label}: {count} (seed {seed})"]
    lines.append(f"{'trial':>5}  {'outcomes':<17}{'successes':>10}{'s/fragment':>12}")
    for i, trial in enumerate(trials, start=1):
        note = f"  sim error: {trial.sim_error}" if trial.sim_error else ""
        if unpicked := unpicked_note(vars(trial)):
            note += f"  ({unpicked})"
        successes = sum(o == "-" for o in trial.outcomes)
        lines.append(
            f"{i:>5}  {','.join(trial.outcomes):<17}{f'{successes}/{len(trial.outcomes)}':>10}{trial.time_per_fragment_s:>12.2f}{note}"
        )
    total = totals(trials)
    picks = max(total["picks"], 1)
    lines.append(
        f"total  success {total['success']}/{total['picks']} ({100 * total['success'] / picks:.1f}%), "
        f"A {total['A']}, B {total['B']}, C {total['C']}; {total['time_per_fragment_s']:.2f} s per fragment"
    )
    if unpicked := unpicked_note(total):
        lines.append(f"       {unpicked}")
    reference = paper.DEBRIDEMENT_RESULTS.get((calibrator, fragment))
    if reference:
        n, (low, high) = paper.DEBRIDEMENT_PICKS_PER_CELL, paper.TIME_PER_FRAGMENT_S
        lines.append(
            f"paper  success {reference['success']}/{n} ({100 * reference['success'] / n:.1f}%), "
            f"A {reference['A']}, B {reference['B']}, C {reference['C']}; {low}-{high} s per fragment"
        )
    phases = ", ".join(
        f"{name.replace('_', ' ')} {total['phase_s'][name]:.2f} ({paper.DEBRIDEMENT_PHASE_S[name]:.2f})" for name in total["phase_s"]
    )
    lines.append(f"phases, s (paper): {phases}")
    if total["sim_errors"]:
        lines.append(f"{total['sim_errors']} trial(s) ended with a physics failure")
    return "\n".join(lines)


def save_trials(trials: list[Trial], path: str | Path, meta: dict[str, Any]) -> Path:
    """Write the trials, totals, the run's settings and the paper's cell (if any) as JSON."""
    data = {
        **meta,
        "trials": [
            {
                "outcomes": ",".join(t.outcomes),
                "time_per_fragment_s": t.time_per_fragment_s,
                "phase_s": t.phase_s,
                "sim_error": t.sim_error,
                "unpicked_delivered": t.unpicked_delivered,
                "unpicked_lost": t.unpicked_lost,
            }
            for t in trials
        ],
        "totals": totals(trials),
        "paper": paper.DEBRIDEMENT_RESULTS.get((str(meta.get("calibrator")), str(meta.get("fragment")))),
    }
    return atomic_write_json(path, data, indent=1)


def plot_outcome_grid(trials: list[Trial], path: str | Path, title: str) -> Path:
    """A trials x picks grid, each cell coloured (and lettered) by its outcome."""
    import matplotlib  # lazily: matplotlib takes a second to import

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    keys = list(OUTCOME_COLOURS)
    width = max([len(t.outcomes) for t in trials] + [paper.FRAGMENTS_PER_TRIAL])
    grid = np.full((len(trials), width), keys.index(""))
    for row, trial in enumerate(trials):
        for col, outcome in enumerate(trial.outcomes):
            grid[row, col] = keys.index(outcome)
    fig, ax = plt.subplots(figsize=(0.55 * width + 2.2, 0.32 * len(trials) + 1.4))
    ax.imshow(grid, cmap=ListedColormap([OUTCOME_COLOURS[k] for k in keys]), vmin=0, vmax=len(keys) - 1, aspect="auto")
    for row, trial in enumerate(trials):
        for col, outcome in enumerate(trial.outcomes):
            if outcome != "-":
                ax.text(col, row, outcome, ha="center", va="center", color="white", fontsize=8, fontweight="bold")
    ax.set_xticks(range(width), [str(i + 1) for i in range(width)])
    ax.set_yticks(range(len(trials)), [str(i + 1) for i in range(len(trials))])
    ax.set_xlabel("pick")
    ax.set_ylabel("trial")
    handles = [Patch(color=OUTCOME_COLOURS[k], label=OUTCOME_NAMES[k]) for k in keys]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    try:
        return atomic_savefig(fig, path, dpi=110)
    finally:
        plt.close(fig)


def save_cell(trials: list[Trial], *, stem: str | Path, meta: dict[str, Any], label: str, text: str | None = None) -> dict[str, Path]:
    """Write one cell of the table beside ``stem``: ``.json`` (:func:`save_trials`), ``.png``
    (the outcome grid, titled with ``label``) and, given ``text``, ``.txt``.

    Returns:
        The written paths by suffix ("json", "png", "txt").
    """
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    written = {"json": save_trials(trials, stem.with_name(f"{stem.name}.json"), meta)}
    if text is not None:
        written["txt"] = atomic_write_text(stem.with_name(f"{stem.name}.txt"), text + "\n")
    written["png"] = plot_outcome_grid(trials, stem.with_name(f"{stem.name}.png"), f"Debridement outcomes: {label} ({len(trials)} trials)")
    return written
