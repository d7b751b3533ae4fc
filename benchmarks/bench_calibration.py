"""The paper's calibration table in simulation, with the wall time of every stage.

Run: python benchmarks/bench_calibration.py [--out DIR] [--trajectories 57] [--epochs 1000]
With the paper's budgets (the defaults) issue 5's targets are the paper's means within
+-25%: RBT 4.55 mm, DNN 2.14 mm, DNN+RF 1.08 mm. A fresh --out (the default is a new
temporary folder) times every stage; an existing run folder is resumed from its cache.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import dvrk_gym  # noqa: F401
from dvrk_gym import paper
from dvrk_gym.calibration.benchmark import format_table
from dvrk_gym.calibration.models.dnn import MAX_EPOCHS
from dvrk_gym.calibration.phase1 import MAX_TRAJECTORIES
from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
from dvrk_gym.cli.options import check_flag_bounds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="run folder (default: a new temporary one)")
    parser.add_argument("--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES, help="Phase I trajectories (default: %(default)s)")
    parser.add_argument("--epochs", type=int, default=paper.DNN_EPOCHS, help="DNN epochs (default: %(default)s)")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"trajectories": (1, MAX_TRAJECTORIES), "epochs": (1, MAX_EPOCHS)})
    out = args.out or Path(tempfile.mkdtemp(prefix="dvrk_gym_calibration_"))
    start = time.perf_counter()
    result = run_calibration(out, PipelineConfig(n_trajectories=args.trajectories, dnn_epochs=args.epochs), progress=False)
    total = time.perf_counter() - start
    print(format_table(result["table"]))
    print()
    phase1 = result["phase1"]
    raw, kept = paper.PHASE1_RAW_SAMPLES, paper.PHASE1_KEPT_SAMPLES
    print(
        f"Phase I: {phase1.n_raw} raw samples, {phase1.n_kept} kept "
        f"({phase1.n_kept / phase1.n_raw:.0%}; the paper: {raw}, {kept}, {kept / raw:.0%})"
    )
    print(f"{'stage':<12}{'wall s':>10}")
    for stage, seconds in result["timings_s"].items():
        print(f"{stage:<12}{seconds:>10.1f}")
    print(f"{'total':<12}{total:>10.1f}")
    print(f"DNN training ({phase1.n_kept} rows x {args.epochs} epochs, one thread): {result['timings_s'].get('dnn', float('nan')):.1f} s")
    print(f"run folder: {out}")


if __name__ == "__main__":
    main()
