"""The paper's calibration table run by run: the real robot's records beside the simulated robot's touches.

The authors recorded every touch of the runs that measured the paper's table, and the Phase II
pushes of the same days (:func:`dvrk_gym.calibration.datasets.load_paper_table_runs`). The
rigid body's runs were lifted 4 to 9 mm (:data:`~dvrk_gym.paper.TABLE_LIFT_MM`; their
author: height was a main reason for its low performance), and the last three first clipped
the predicted height into a band of the robot's frame whose top lies 0.3 mm under the jaws
pushed onto the paper in the authors' first mapping (:data:`~dvrk_gym.paper.TABLE_Z_BAND_M`,
:data:`~dvrk_gym.paper.TABLE_CLIPPED`); ``dvrk-gym evaluate`` does the same by default
(:mod:`dvrk_gym.evaluation.table_protocol`). The network's runs sent its predictions as they were.
The robot was sent there, and a person drew a box around the end effector in the left image;
the table's error is the distance from the circle's centre to the box's.

Per method and setting, over the 35 circles, for the real robot and for the simulated one (a
calibration run's calibrators on GridTouch-v0 with ``dvrk-gym evaluate``'s seeds, touched
the authors' way, as ``dvrk-gym evaluate`` touches: the same lifts, and the band, where they
clipped, carried over by where each robot reports its jaws pushed onto the circles):

- the table's error, px (the rigid body's also raw: its predictions sent as they are,
  ``dvrk-gym evaluate --protocol raw``);
- the prediction's height (clipped, in a run that clipped: the records keep no other) over
  the jaws pushed onto the paper, mm (median): over a plane through the reported positions
  of the Phase II pushes at that yaw (the real robot's from the same day as the run,
  :data:`~dvrk_gym.paper.TABLE_PUSH_ROUND`; the simulated robot's from where the simulated person's push leaves
  the reported jaws at each touch, GridTouch's ``human_correction``);
- the sent height over that plane, mm (median): how high the jaws hung, or how far under the
  paper they were sent;
- the share of touches sent under the plane;

and each row's mean (over the six settings for the error, as the paper averages; over the
five fixed yaws for the rest: the random setting has no real pushes). Before the rows: how
the real rigid body's miss to the right in the image follows how deep it was sent; after
them: for the rigid body's touches sent more than 1 mm under the pushed jaws, how far over
the sent height the robot reported itself after the move (the real arm gave way to part of
the depth, and so does the simulated one, :data:`dvrk_gym.sim.identified.PAPER_CONTACT`,
identified from these records by ``benchmarks/identify_contact.py``); where the Phase I
kept rows lie over the pushed jaws, real (the first round of pushes, the nearest in time)
and simulated; how the paper's plane tilts in each robot's
frame (through the pushes, and through the Phase I rows, which followed the authors' plane
fitted through four corners); and, per yaw, the mean of the Phase II pushes
(how far a person moved the jaws from the network's prediction onto the circle, in the
robot's x and y), real (both rounds) and simulated (the calibration run's Phase II), with
how far the mean y spreads over the yaws. Between the last two: how each method's sent
heights scatter about a plane through them, real and simulated, and whether a circle's
error there repeats from run to run (as it does when the runs share one detection of the
circles).

The rigid body's dive identifies the tape detector's right-image shift
(``benchmarks/identify_tape_shift.py``, which uses this script's statistics).

About 15 s after the calibration:

    dvrk-gym calibrate --out runs/cal
    python benchmarks/fidelity_table_runs.py --calibration runs/cal
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from unittest import mock

import gymnasium as gym
import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.benchmark import BENCHMARK_SEED, YAW_SETTINGS, touch_grid_episodes
from dvrk_gym.calibration.datasets import PaperTableRuns, load_paper_phase1, load_paper_table_runs
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.models.features import nearest_yaw_index
from dvrk_gym.calibration.phase1 import Phase1Data
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.calibration.pipeline import BENCHMARK_SEED_OFFSET, SETTINGS_STAMP, PipelineConfig, read_pipeline_settings
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.evaluation.table_protocol import RAW, HeightRule, RuledPolicy, carried_band, paper_rules
from dvrk_gym.fidelity.contact import height_over_pushes, pushes_of_run
from dvrk_gym.fidelity.statistics import plane_slope, tilt_deg
from dvrk_gym.sim.world import DvrkWorld
from dvrk_gym.sim.world_config import WorldConfig
from dvrk_gym.utils.run_folder import check_made_here

FIXED_YAWS = 5
"""The table's first five settings are the fixed yaws, which have Phase II pushes."""
STATISTICS = (
    "table error, px",
    "prediction over the pushed jaws, mm",
    "sent over the pushed jaws, mm",
    "sent under the pushed jaws, share",
)
GIVE_DEPTH_M = 1e-3
"""A touch sent deeper than this under the pushed jaws counts for :func:`give`, metres."""


over_plane = height_over_pushes
"""Heights (n,) m of points (n, 3) m over the plane through the pushed jaws (m, 3) m."""


def statistics(pixels: np.ndarray, predicted: np.ndarray, sent: np.ndarray, pushed: np.ndarray | None) -> tuple[float, ...]:
    """The statistics (:data:`STATISTICS`) of one setting's touches: errors (n,) px; predicted and
    sent positions (n, 3) m; the pushed jaws' positions (m, 3) m, or None (NaN heights)."""
    if pushed is None:
        return (float(np.mean(pixels)), np.nan, np.nan, np.nan)
    sent_over = over_plane(sent, pushed)
    return (
        float(np.mean(pixels)),
        1e3 * float(np.median(over_plane(predicted, pushed))),
        1e3 * float(np.median(sent_over)),
        float(np.mean(sent_over < 0.0)),
    )


real_pushed_jaws = pushes_of_run
"""The real Phase II pushes (n, 3) m at a fixed-yaw setting's yaw, from the day of the method's runs."""


def sliding(runs: PaperTableRuns, label: str) -> list[float]:
    """Per fixed yaw, the correlation over a real run's touches between where the end effector
    landed right of the circle in the image (px) and how high it was sent over the pushed jaws."""
    correlations = []
    for setting in range(FIXED_YAWS):
        mine = (runs.method == label) & (runs.setting == setting)
        right = runs.end_effector_px[mine, 0] - runs.circle_px[mine, 0]
        correlations.append(float(np.corrcoef(right, over_plane(runs.sent[mine], real_pushed_jaws(runs, label, setting)))[0, 1]))
    return correlations


def rows_over_pushes(positions: np.ndarray, yaws: np.ndarray, pushed: np.ndarray, pushed_yaws: np.ndarray) -> np.ndarray:
    """Heights (n,) m of Phase I rows' reported ``positions`` (n, 3) m over the plane through the
    pushes at the paper's yaw nearest each row's ``yaws`` (n,) rad; ``pushed`` (m, 3) m at
    ``pushed_yaws`` (m,) rad."""
    heights = np.full(len(positions), np.nan)
    nearest = nearest_yaw_index(yaws)
    for index, yaw in enumerate(np.deg2rad(paper.PHASE2_YAWS_DEG)):
        rows, at_yaw = nearest == index, np.isclose(pushed_yaws, yaw)
        heights[rows] = over_plane(positions[rows], pushed[at_yaw])
    return heights


def plane_tilt(positions: np.ndarray) -> str:
    """The tilt (deg) and slopes along x and y (mm per mm) of the least-squares plane through
    ``positions`` (n, 3) m, as a line of text (:func:`~dvrk_gym.fidelity.statistics.plane_slope`)."""
    slope_x, slope_y = plane_slope(positions)
    return f"{tilt_deg((slope_x, slope_y)):5.1f} deg   x {slope_x:+.3f}   y {slope_y:+.3f}"


def push_means(yaws: np.ndarray, moves: np.ndarray) -> np.ndarray:
    """Per paper yaw (-90 .. 90 degrees), the mean of the Phase II ``moves`` (n, 3) m made
    nearest it (``yaws`` (n,) rad), (5, 3) m: where the network's prediction left the jaws
    against the circle, which a person's push measures. Raises ValueError if a yaw has none."""
    nearest = nearest_yaw_index(yaws)
    if len(moves) != len(yaws) or np.bincount(nearest, minlength=len(paper.PHASE2_YAWS_DEG)).min() == 0:
        raise ValueError(f"every paper yaw needs a push; got {len(yaws)} yaws and {len(moves)} moves")
    return np.array([moves[nearest == k].mean(axis=0) for k in range(len(paper.PHASE2_YAWS_DEG))])


def height_scatter(sent: list[np.ndarray]) -> tuple[list[float], float]:
    """How the sent heights scatter about a plane through them, per fixed yaw (sd of the
    residuals, mm; ``sent``: per yaw (35, 3) m, the circles in one order), and the median over
    pairs of yaws of the correlation between one circle's residuals: near 1 when each circle
    keeps its error from run to run (one detection of the circles), near 0 when each run
    draws its own."""
    residuals = [height_over_pushes(points, points) for points in sent]  # each set's heights over its own plane
    correlation = np.corrcoef(np.array(residuals))[np.triu_indices(len(residuals), k=1)]
    return [1e3 * float(np.std(r)) for r in residuals], float(np.median(correlation))


def print_height_scatter(runs: PaperTableRuns, simulated: dict[str, list[Touches]]) -> None:
    """The :func:`height_scatter` of each method's real runs and of its simulated touches (the authors' way)."""
    print(
        "the sent heights' scatter about a plane through them (sd, mm; yaw -90 to 90), one circle's correlation between runs"
        " (median), and how far the real circles' detected centres move between runs (the most, px)"
    )
    for label in paper.METHOD_LABELS.values():
        mine = [(runs.method == label) & (runs.setting == k) for k in range(FIXED_YAWS)]
        moved = float(np.ptp(np.array([runs.circle_px[m] for m in mine]), axis=0).max())
        for who, sent in (
            ("real", [runs.sent[m] for m in mine]),
            ("sim, the authors' way", [t.sent for t in simulated[label][:FIXED_YAWS]]),
        ):
            spread, correlation = height_scatter(sent)
            centres = f"   centres move {moved:.0f} px" if who == "real" else ""
            print(f"  {label:<8s}{who:<26s}" + "".join(f"{v:6.2f}" for v in spread) + f"   correlation {correlation:+.2f}{centres}")


def real_table(runs: PaperTableRuns) -> dict[str, list[tuple[float, ...]]]:
    """Per method, per setting, the statistics of the real runs (NaN heights for the random setting)."""
    table: dict[str, list[tuple[float, ...]]] = {}
    for label in paper.METHOD_LABELS.values():
        table[label] = []
        for setting, lift in enumerate(paper.TABLE_LIFT_MM[label]):
            mine = (runs.method == label) & (runs.setting == setting)
            sent = runs.sent[mine]
            pushed = real_pushed_jaws(runs, label, setting) if setting < FIXED_YAWS else None
            table[label].append(statistics(runs.pixel_error[mine], sent - [0.0, 0.0, 1e-3 * lift], sent, pushed))
    return table


@dataclass(frozen=True)
class Touches:
    """One setting's 35 touches: the table's errors (n,) px; the predicted, sent and reported
    positions (n, 3) m (reported: where the robot reported itself after the move); the jaws
    pushed onto the circles (n, 3) m."""

    pixels: np.ndarray
    predicted: np.ndarray
    sent: np.ndarray
    reported: np.ndarray
    pushed: np.ndarray


def simulated_touches(env: gym.Env, policy: CalibratedPolicy, rules: Sequence[HeightRule], seed: int = BENCHMARK_SEED) -> list[Touches]:
    """Per setting, the simulated touches sent by that setting's height rule (``rules``:
    :mod:`dvrk_gym.evaluation.table_protocol`). Setting k's pass is seeded with
    ``seed + k``, as ``dvrk-gym evaluate`` seeds it (``seed``: the run's seed plus
    :data:`~dvrk_gym.calibration.pipeline.BENCHMARK_SEED_OFFSET`)."""
    settings = []
    for k, ((_, yaw), rule) in enumerate(zip(YAW_SETTINGS, rules, strict=True)):
        touch = RuledPolicy(policy, rule)
        episodes = touch_grid_episodes(env, touch, yaw, seed=seed + k)
        reported = np.array([e.final_info["reported_position"] for e in episodes])
        pushed = reported + np.array([e.final_info["human_correction"] for e in episodes])
        pixels = np.array([e.metrics["pixel_error"] for e in episodes])
        settings.append(Touches(pixels, np.array(touch.predicted), np.array(touch.sent), reported, pushed))
    return settings


def simulated_table(
    env: gym.Env, policy: CalibratedPolicy, rules: Sequence[HeightRule], seed: int = BENCHMARK_SEED
) -> list[tuple[float, ...]]:
    """Per setting, the statistics of :func:`simulated_touches` (seeded from ``seed``)."""
    return touch_statistics(simulated_touches(env, policy, rules, seed))


def touch_statistics(touches: list[Touches]) -> list[tuple[float, ...]]:
    """Per setting, the statistics (:data:`STATISTICS`) of its touches."""
    return [statistics(t.pixels, t.predicted, t.sent, t.pushed) for t in touches]


def give(sent: list[np.ndarray], reported: list[np.ndarray], pushed: list[np.ndarray]) -> tuple[int, float, float]:
    """How far the arm reported itself over where it was sent, where it was sent more than
    :data:`GIVE_DEPTH_M` under the plane through the pushed jaws (per fixed yaw: sent and
    reported (n, 3) m, pushed (m, 3) m): the number of such touches, and the medians of how
    deep they were sent and of how far over the sent height they were reported, mm."""
    depth, rise = [], []
    for s, r, p in zip(sent, reported, pushed, strict=True):
        under = -over_plane(s, p)
        deep = under > GIVE_DEPTH_M
        depth.append(under[deep])
        rise.append((r[:, 2] - s[:, 2])[deep])
    depths, rises = np.concatenate(depth), np.concatenate(rise)
    if len(depths) == 0:
        return 0, np.nan, np.nan
    return len(depths), 1e3 * float(np.median(depths)), 1e3 * float(np.median(rises))


def print_give(who: str, counted: tuple[int, float, float]) -> None:
    n, depth, rise = counted
    share = f"{rise / depth:.2f} of the depth" if n else "-"
    print(f"  {who:<34s}{n:>4d} touches  sent {depth:5.1f} mm under, reported {rise:5.1f} mm over the sent height ({share})")


def print_rows(name: str, rows: dict[str, list[tuple[float, ...]]]) -> None:
    """Print each statistic's rows (who: one value per setting) and their mean: over the six
    settings for the error, as the paper averages, and over the fixed yaws for the rest."""
    print(name)
    for i, statistic in enumerate(STATISTICS):
        form = "{:>9.2f}" if statistic.endswith("share") else "{:>9.1f}"
        for who, cells in rows.items():
            values = np.array([cell[i] for cell in cells])
            text = "".join(form.format(v) if np.isfinite(v) else f"{'-':>9s}" for v in values)
            mean = np.mean(values) if i == 0 else np.mean(values[:FIXED_YAWS])
            print(f"  {statistic if who == next(iter(rows)) else '':<38s}{who:<22s}{text}{form.format(mean)}")


def report(calibration: Path, config: PipelineConfig, runs: PaperTableRuns) -> None:
    """Print the comparison for the calibration run in ``calibration`` (made with ``config``)."""
    phase2 = Phase2Data.load(calibration / "phase2.npz")
    band = carried_band(phase2.corrected[:, 2])
    print(
        f"the authors' band {1e3 * paper.TABLE_Z_BAND_M[0]:.1f} to {1e3 * paper.TABLE_Z_BAND_M[1]:.1f} mm (their pushed jaws at "
        f"{1e3 * paper.TABLE_PAPER_Z_M:.1f}); simulated {1e3 * band[0]:.1f} to {1e3 * band[1]:.1f} mm (pushed jaws at "
        f"{1e3 * float(np.mean(phase2.corrected[:, 2])):.1f}, mean of {len(phase2.corrected)} Phase II rows)"
    )
    print(f"instrument: {config.env_kwargs()}")
    env = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
    try:
        _print_comparison(calibration, env, phase2, runs, config.seed + BENCHMARK_SEED_OFFSET)
    finally:
        env.close()


def _print_comparison(calibration: Path, env: gym.Env, phase2: Phase2Data, runs: PaperTableRuns, seed: int) -> None:
    """The rows of :func:`report`, touched on ``env`` with ``dvrk-gym evaluate``'s seeds (from
    ``seed``); the authors' band carried over by ``phase2``'s pushes."""
    real = real_table(runs)
    print(
        "real RBT: correlation of how far right of the circle the end effector landed (px) with how high it was sent "
        "(yaw -90 to 90): " + ", ".join(f"{c:+.2f}" for c in sliding(runs, "RBT"))
    )
    print(f"  {'':<60s}" + "".join(f"{label:>9s}" for label, _ in YAW_SETTINGS) + f"{'mean':>9s}")
    rigid_body: dict[str, list[Touches]] = {}  # the rigid body's simulated touches, kept for its give below
    authors_way: dict[str, list[Touches]] = {}  # every method's, for the heights' scatter
    for name, label in paper.METHOD_LABELS.items():
        policy = CalibratedPolicy(load_calibrator(calibration, name)[0])
        lifts, clipped = paper.TABLE_LIFT_MM[label], paper.TABLE_CLIPPED[label]
        authors = paper_rules(label, phase2.corrected[:, 2])
        raw = (RAW,) * len(YAW_SETTINGS)
        touched = {"sim, the authors' way": simulated_touches(env, policy, authors, seed)}
        authors_way[label] = touched["sim, the authors' way"]
        if authors != raw:
            touched["sim, raw"] = simulated_touches(env, policy, raw, seed)
        if label == "RBT":
            rigid_body = touched
        rows = {"real": real[label]}
        rows.update({who: touch_statistics(touches) for who, touches in touched.items()})
        clips = (
            "clipped " + ", ".join(s for s, c in zip(paper.CALIBRATION_SETTINGS, clipped, strict=True) if c)
            if any(clipped)
            else "not clipped"
        )
        print_rows(f"{label} (lifts {', '.join(f'{v:.0f}' for v in lifts)} mm; {clips})", rows)
    print(
        f"RBT, the touches sent more than {1e3 * GIVE_DEPTH_M:.0f} mm under the pushed jaws (fixed yaws): how far over the sent "
        "height the robot reported itself (the simulated arm gives way as dvrk_gym.sim.identified.PAPER_CONTACT says)"
    )
    settings = [(runs.method == "RBT") & (runs.setting == k) for k in range(FIXED_YAWS)]
    pushes = [real_pushed_jaws(runs, "RBT", k) for k in range(FIXED_YAWS)]
    print_give("real", give([runs.sent[m] for m in settings], [runs.reported[m] for m in settings], pushes))
    for who, touches in rigid_body.items():
        fixed = touches[:FIXED_YAWS]
        print_give(who, give([t.sent for t in fixed], [t.reported for t in fixed], [t.pushed for t in fixed]))
    real_X, real_y = load_paper_phase1()
    first_round = runs.push_round == 0  # the pushes nearest in time to the Phase I collection
    real_heights = rows_over_pushes(real_y, real_X[:, 3], runs.push_after[first_round], runs.push_yaw[first_round])
    phase1 = Phase1Data.load(calibration / "phase1.npz")
    kept = phase1.kept
    heights = rows_over_pushes(phase1.reported_position[kept], phase1.orientation[kept, 0], phase2.corrected, phase2.orientation[:, 0])
    for who, values in (("real", real_heights), ("sim", heights)):
        low, middle, high = np.percentile(1e3 * values, [5, 50, 95])
        print(f"Phase I kept rows over the pushed jaws, {who}: {low:.1f} / {middle:.1f} / {high:.1f} mm (5th / 50th / 95th percentile)")
    print("the paper's plane in the robot's frame: tilt from the base xy-plane (deg), and its slopes along x and y (mm per mm)")
    planes = [(f"real Phase II pushes, round {k}", runs.push_after[runs.push_round == k]) for k in sorted(set(runs.push_round.tolist()))]
    planes += [
        ("real Phase I kept rows", real_y),
        ("sim Phase II pushes", phase2.corrected),
        ("sim Phase I kept rows", phase1.reported_position[kept]),
    ]
    for who, positions in planes:
        print(f"  {who:<34s}" + plane_tilt(positions))
    print_height_scatter(runs, authors_way)
    _print_push_means(runs, phase2)


def _print_push_means(runs: PaperTableRuns, phase2: Phase2Data) -> None:
    """The Phase II pushes' mean per yaw (:func:`push_means`), real (both rounds) and simulated (``phase2``)."""
    print(
        "Phase II pushes: how far the person moved the jaws from the network's prediction, mean per yaw (x, y mm, base "
        "frame), and how far the mean y spreads over the yaws"
    )
    print(f"  {'':<24s}" + "".join(f"{yaw:>16.0f}" for yaw in paper.PHASE2_YAWS_DEG) + f"{'y spread':>10s}")
    for who, (_, moves, yaws) in (
        *((f"real, round {k}", real_pushes(runs, k)) for k in (0, 1)),
        ("sim", simulated_pushes(phase2)),
    ):
        means = 1e3 * push_means(yaws, moves)
        cells = "".join(f"{f'{x:+.1f}, {y:+.1f}':>16s}" for x, y in means[:, :2])
        print(f"  {who:<24s}{cells}{np.ptp(means[:, 1]):>10.1f}")


@contextlib.contextmanager
def marker_noise_replaced(**changes: Any) -> Iterator[None]:
    """While open, every new simulated world's red-tape detector has the fields ``changes`` of
    :class:`~dvrk_gym.sim.endoscope.noise.DetectionNoise` in place of its own (the endoscope's
    true baseline follows a changed right-image shift, as the world derives it). A benchmark's
    what-if, not an option of the package; undone on exit. (Nested, the outer one wins.)"""
    original = DvrkWorld.__init__

    def init(self: DvrkWorld, config: WorldConfig | None = None) -> None:
        config = config or WorldConfig()
        original(self, dataclasses.replace(config, marker_noise=dataclasses.replace(config.marker_noise, **changes)))

    with mock.patch.object(DvrkWorld, "__init__", init):
        yield


def add_calibration_argument(parser: argparse.ArgumentParser) -> None:
    """Give a benchmark's parser ``--calibration DIR``, a ``dvrk-gym calibrate`` folder (read with :func:`read_calibration`)."""
    parser.add_argument("--calibration", type=Path, required=True, help="a folder of dvrk-gym calibrate")


def read_calibration(parser: argparse.ArgumentParser, folder: Path) -> PipelineConfig:
    """The settings a calibration run ``folder`` was made with. A folder with no settings stamp,
    or one another dvrk_gym made (its rows would be mixed with this version's simulation),
    is a usage error of ``parser`` (exit 2)."""
    try:
        settings = read_pipeline_settings(folder)
        check_made_here(folder, SETTINGS_STAMP, remedy="make it again with this version: dvrk-gym calibrate --out NEW_FOLDER")
    except ValueError as error:
        parser.error(str(error))
    if settings is None:
        parser.error(f"{folder} is not a calibration run folder (no settings stamp); make one with dvrk-gym calibrate --out")
    return PipelineConfig.from_settings(settings)


def simulated_pushes(phase2: Phase2Data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A simulated Phase II's pushes as :func:`real_pushes` gives the real ones: the network's
    predictions (n, 3) m, how far the person moved the jaws from them (n, 3) m, the yaws (n,) rad."""
    return phase2.commanded, phase2.corrected - phase2.commanded, phase2.orientation[:, 0]


def real_pushes(runs: PaperTableRuns, round_index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One round of the real Phase II pushes (:data:`PUSH_ROUND`), in the order made: the network's
    predictions (n, 3) m, how far the person moved the jaws from them (n, 3) m, and the yaws (n,) rad."""
    mine = runs.push_round == round_index
    return runs.push_predicted[mine], (runs.push_after - runs.push_predicted)[mine], runs.push_yaw[mine]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_calibration_argument(parser)
    args = parser.parse_args()
    report(args.calibration, read_calibration(parser, args.calibration), load_paper_table_runs())
