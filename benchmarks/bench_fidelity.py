"""Issue 15's fidelity targets over several instruments and Phase I collections, in one table.

``dvrk-gym fidelity`` compares one simulated Phase I with the authors' real rows. The targets
ask for every statistic within its bound "for the default instrument and for instruments it
was not fitted on", and a single collection's per-yaw statistics move by a few degrees from
one collection seed to the next. This runs ``dvrk-gym fidelity``'s comparison
(:func:`dvrk_gym.fidelity.comparison.run_fidelity`) for every pair of ``--bias-seeds``
(instrument 0 is the identified one; the others are drawn around it and were not fitted)
and ``--seeds`` (the collection), and prints each statistic's real value, its simulated
value in every run, and in how many runs it meets its target; then each run's count of
statistics met. About a minute a run on a quiet machine at the paper's 57 trajectories;
``--workers 2`` runs two at a time.

    python benchmarks/bench_fidelity.py --bias-seeds 0 1 2 3 --seeds 0 1 [--workers 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.phase1 import MAX_TRAJECTORIES
from dvrk_gym.cli.options import check_flag_bounds
from dvrk_gym.fidelity.comparison import ComparisonRow, run_fidelity
from dvrk_gym.fidelity.statistics import finite_or_none
from dvrk_gym.utils.atomic import atomic_write_text
from dvrk_gym.utils.checks import check_endoscope_resolution

JSON_NAME = "bench_fidelity.json"


@dataclass(frozen=True)
class Run:
    """One simulated collection's comparison with the real rows.

    Attributes:
        bias_seed: the instrument (0: the identified one).
        seed: the collection's seed.
        kept_rows: the simulated rows kept, of ``raw_rows``.
        raw_rows: the simulated rows collected.
        rows: the comparison, statistic by statistic (``dvrk-gym fidelity``'s).
    """

    bias_seed: int
    seed: int
    kept_rows: int
    raw_rows: int
    rows: tuple[ComparisonRow, ...]

    @property
    def label(self) -> str:
        return f"i{self.bias_seed} s{self.seed}"

    @property
    def passed(self) -> int:
        return sum(row.passed for row in self.rows)


def collect(bias_seed: int, seed: int, trajectories: int, resolution: tuple[int, int]) -> Run:
    """One run of ``dvrk-gym fidelity --bias paper`` (no progress bar), kept as its comparison."""
    run = run_fidelity(
        bias="paper",
        bias_seed=bias_seed,
        n_trajectories=trajectories,
        seed=seed,
        camera_resolution=resolution,
        progress=False,
        bootstrap_replicates=0,  # the grid's spread is over its runs
    )
    return Run(bias_seed, seed, run.sim.rows, run.sim_raw_rows, tuple(run.rows))


def run_grid(bias_seeds: Sequence[int], seeds: Sequence[int], trajectories: int, resolution: tuple[int, int], workers: int) -> list[Run]:
    """Every (instrument, collection) pair, in that order; ``workers`` processes at a time."""
    pairs = [(bias_seed, seed) for bias_seed in bias_seeds for seed in seeds]
    if workers == 1 or len(pairs) == 1:
        return [collect(bias_seed, seed, trajectories, resolution) for bias_seed, seed in pairs]
    # spawn: a forked PyBullet client or torch thread pool is not safe in the child
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(collect, bias_seed, seed, trajectories, resolution) for bias_seed, seed in pairs]
        return [future.result() for future in futures]


def _value(row: ComparisonRow) -> str:
    return "nan" if not np.isfinite(row.sim) else f"{row.sim:.2f}"


def format_grid(runs: Sequence[Run]) -> str:
    """Each statistic's real value, target, simulated value per run (``*`` marks a miss) and
    runs meeting the target; then each run's statistics met."""
    names = [row.name for row in runs[0].rows]
    if any([row.name for row in run.rows] != names for run in runs):
        raise ValueError("the runs compare different statistics")
    width = max(len(name) for name in names)
    cells = [f"{run.label:>9}" for run in runs]
    lines = [f"{'statistic':<{width}}  {'real':>7}  {'target':>15}  {' '.join(cells)}  met"]
    for index, name in enumerate(names):
        first = runs[0].rows[index]
        values = " ".join(f"{_value(run.rows[index]) + ('' if run.rows[index].passed else '*'):>9}" for run in runs)
        met = sum(run.rows[index].passed for run in runs)
        lines.append(f"{name:<{width}}  {first.real:>7.2f}  {first.target:>15}  {values}  {met}/{len(runs)}")
    lines.append("")
    for run in runs:
        lines.append(
            f"instrument {run.bias_seed}, collection seed {run.seed}: {run.passed} of {len(run.rows)} statistics within target "
            f"({run.kept_rows} of {run.raw_rows} rows kept)"
        )
    always = sum(all(run.rows[index].passed for run in runs) for index in range(len(names)))
    lines.append(f"{always} of {len(names)} statistics within target in every run (* marks a miss)")
    return "\n".join(lines)


def grid_dict(runs: Sequence[Run], settings: dict[str, object]) -> dict[str, object]:
    """The runs as JSON-ready data."""
    return {
        "settings": settings,
        "runs": [
            {
                "bias_seed": run.bias_seed,
                "seed": run.seed,
                "kept_rows": run.kept_rows,
                "raw_rows": run.raw_rows,
                "passed": run.passed,
                "statistics": [
                    {"statistic": row.name, "real": finite_or_none(row.real), "sim": finite_or_none(row.sim), "passed": row.passed}
                    for row in run.rows
                ],
            }
            for run in runs
        ],
    }


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bias-seeds", type=int, nargs="+", default=[0, 1, 2, 3], help="instruments (default: 0 1 2 3)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="collection seeds (default: 0)")
    parser.add_argument(
        "--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="Phase I trajectories a run (the paper: %(default)s)"
    )
    parser.add_argument("--resolution", type=int, nargs=2, default=paper.ENDOSCOPE_RESOLUTION_PX, metavar=("W", "H"))
    parser.add_argument("--workers", type=int, default=1, help="runs at a time, a process each (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None, help=f"also write {JSON_NAME} into this folder")
    args = parser.parse_args(argv)
    check_flag_bounds(parser, args, {"trajectories": (1, MAX_TRAJECTORIES), "workers": (1, 64)})
    for flag, values in (("--bias-seeds", args.bias_seeds), ("--seeds", args.seeds)):
        if len(values) > 100 or any(not 0 <= value < 2**31 for value in values) or len(set(values)) != len(values):
            parser.error(f"{flag} must be at most 100 distinct integers in [0, 2**31), got {values}")
    try:
        resolution = check_endoscope_resolution("--resolution", args.resolution)
    except ValueError as error:
        parser.error(str(error))
    runs = run_grid(args.bias_seeds, args.seeds, args.trajectories, resolution, args.workers)
    print(format_grid(runs))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        settings = {"bias": "paper", "trajectories": args.trajectories, "camera_resolution": list(resolution)}
        path = atomic_write_text(args.out / JSON_NAME, json.dumps(grid_dict(runs, settings), indent=1))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
