"""A 5-instrument x 3-calibrator sweep on local processes and on a Dask LocalCluster: wall times, same numbers?

Run: python benchmarks/bench_sweep.py [--workers 2] [--bias-seeds 0-4] [--trajectories 3] [--epochs 20]
[--resolution 640 360] [--paper]
Runs the sweep twice from scratch, in two new temporary folders: on a pool of --workers local
processes (the default executor of ``dvrk-gym sweep``), then on a ``dask.distributed``
LocalCluster of --workers single-thread worker processes (what ``--scheduler`` reaches).
Prints each one's wall time (the cluster's start-up included, its own line) and whether
every number of the two tables is the same, bit for bit (wall-time columns aside). The
default budget makes a unit take seconds (about 1.5 min for both sweeps on 2 quiet cores);
--paper uses the paper's (57 trajectories, 1000 epochs, 1920 x 1080: about 2.5 min a unit).
Needs dask[distributed] (the dev or dask extra).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from distributed import LocalCluster

from dvrk_gym import paper
from dvrk_gym.calibration.models.dnn import MAX_EPOCHS
from dvrk_gym.calibration.phase1 import MAX_TRAJECTORIES
from dvrk_gym.calibration.pipeline import PipelineConfig
from dvrk_gym.cli.options import check_flag_bounds
from dvrk_gym.parallel.dask_executor import DaskExecutor
from dvrk_gym.sweep import LocalExecutor, SweepResult, SweepSettings, format_rows, parse_calibrators, parse_int_list, run_sweep
from dvrk_gym.sweep.table import TIME_COLUMNS


def _numbers(result: SweepResult) -> list[dict]:
    return [{key: value for key, value in row.items() if key not in TIME_COLUMNS} for row in result.rows]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="local processes, and Dask workers (default: %(default)s)")
    parser.add_argument("--bias-seeds", default="0-4", help="instruments (default: %(default)s)")
    parser.add_argument("--calibrators", default="rbt,dnn,dnn+rf", help="calibrators (default: %(default)s)")
    parser.add_argument("--trajectories", type=int, default=3, help="Phase I trajectories (default: %(default)s)")
    parser.add_argument("--epochs", type=int, default=20, help="DNN epochs (default: %(default)s)")
    parser.add_argument("--resolution", type=int, nargs=2, default=(640, 360), metavar=("W", "H"), help="pixels (default: 640 360)")
    parser.add_argument("--paper", action="store_true", help="the paper's budget instead (57 trajectories, 1000 epochs, 1920 x 1080)")
    args = parser.parse_args()
    check_flag_bounds(
        parser, args, {"workers": (1, 64), "trajectories": (1, MAX_TRAJECTORIES), "epochs": (1, MAX_EPOCHS), "resolution": (None, None)}
    )
    if args.paper:
        pipeline = PipelineConfig()
    else:
        pipeline = PipelineConfig(n_trajectories=args.trajectories, dnn_epochs=args.epochs, camera_resolution=tuple(args.resolution))
    settings = SweepSettings(
        bias_seeds=parse_int_list(args.bias_seeds, "--bias-seeds"), calibrators=parse_calibrators(args.calibrators), pipeline=pipeline
    )
    width, height = pipeline.camera_resolution
    budget = f"{pipeline.n_trajectories} trajectories, {pipeline.dnn_epochs} epochs, {width} x {height}"
    print(f"{len(settings.bias_seeds)} instruments x {len(settings.calibrators)} calibrators; {budget}")
    if not args.paper:
        print(f"(the paper's budget: {paper.PHASE1_TRAJECTORIES} trajectories, {paper.DNN_EPOCHS} epochs; --paper)")
    root = Path(tempfile.mkdtemp(prefix="dvrk_gym_bench_sweep_"))

    start = time.perf_counter()
    with LocalExecutor(workers=args.workers) as pool:
        local = run_sweep(settings, root / "local", pool, progress=False)
    local_s = time.perf_counter() - start

    start = time.perf_counter()
    # dashboard_address ":0": any free port for the HTTP server; None still takes 8787 (distributed 2026.8), so two clusters at once warn
    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        cluster_s = time.perf_counter() - start
        with DaskExecutor(cluster.scheduler_address) as executor:
            dask = run_sweep(settings, root / "dask", executor, progress=False)
    dask_s = time.perf_counter() - start

    print(format_rows(local.rows))
    print()
    unit_s = [row["unit_wall_s"] for row in local.rows[:: len(settings.calibrators)]]
    width = max(len(local.executor), len(dask.executor)) + 2
    print(f"{'executor':<{width}}{'wall s':>8}")
    print(f"{local.executor:<{width}}{local_s:>8.1f}")
    print(f"{dask.executor:<{width}}{dask_s:>8.1f}")
    print(f"{'  of which the LocalCluster start-up':<{width}}{cluster_s:>8.1f}")
    print(f"units on local processes: {min(unit_s):.1f}-{max(unit_s):.1f} s each, {sum(unit_s):.1f} s in all")
    same = _numbers(local) == _numbers(dask)
    print(f"identical numbers on both ({len(local.rows)} cells, {len(local.rows[0]) - len(TIME_COLUMNS)} columns each): {same}")
    print(f"tables: {local.csv}, {dask.csv}")


if __name__ == "__main__":
    main()
