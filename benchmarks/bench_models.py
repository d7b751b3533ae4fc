"""Calibration models on the authors' real Phase I data: CV errors and DNN training time.

Run: python benchmarks/bench_models.py            (chosen net, linear, forest; ~8 min)
     python benchmarks/bench_models.py --search   (the paper's full model search + figure)
     python benchmarks/bench_models.py --quick    (smoke run: few epochs, 3 folds)
     python benchmarks/bench_models.py --split contiguous   (the authors' folds; default shuffled)
     python benchmarks/bench_models.py --throughput  (the chosen net's epoch against one plain product, GFLOP/s)

Prints the 10-fold CV table (mean squared L2 error, mm^2; the paper: chosen 3 x 300 ReLU net
2.06, the authors' code on these rows about 1.74, linear 3.76, forest 5.03) and the wall and
CPU time of training the chosen net on all 1,939 rows for 1,000 epochs, on one thread (the
network always trains on one: :mod:`dvrk_gym.calibration.models.dnn`).
"""

from __future__ import annotations

import argparse
import logging
import time

import torch

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.models.dnn import DEFAULT_LEARNING_RATE, MAX_EPOCHS, DNNCalibrator
from dvrk_gym.calibration.search import (
    CHOSEN_NET,
    PAPER_EPOCHS,
    SWEEP_BATCH_SIZE,
    SWEEP_FOLDS,
    ModelSpec,
    format_table,
    paper_models,
    plot_search,
    run_search,
)
from dvrk_gym.cli.options import check_flag_bounds


def _time_training(X, y, epochs: int) -> tuple[float, float]:
    model = DNNCalibrator(epochs=epochs, progress=False)
    wall, cpu = time.perf_counter(), time.process_time()
    model.fit(X, y)
    return time.perf_counter() - wall, time.process_time() - cpu


def _throughput(X, y, epochs: int) -> None:
    """Print the chosen net's full-batch epoch (forward and backward) in GFLOP/s beside one plain
    (rows x units) @ (units x units) float32 product's, on torch's current threads: how far the
    training is from the core's matrix-product speed."""
    model = DNNCalibrator(epochs=epochs, progress=False)
    start = time.perf_counter()
    model.fit(X, y)
    epoch_s = (time.perf_counter() - start) / epochs
    linears = [layer for layer in model.network_ if isinstance(layer, torch.nn.Linear)]
    rows = X.shape[0]
    macs = rows * sum(layer.in_features * layer.out_features for layer in linears)
    first = rows * linears[0].in_features * linears[0].out_features
    flops = 2 * (3 * macs - first)  # forward, weight gradients, and input gradients but the first layer's
    units = model.units
    a, b = torch.randn(rows, units), torch.randn(units, units)
    for _ in range(20):
        a @ b
    repeats = 300
    start = time.perf_counter()
    for _ in range(repeats):
        a @ b
    product_s = (time.perf_counter() - start) / repeats
    product_rate = 2 * rows * units * units / product_s / 1e9
    epoch_rate = flops / epoch_s / 1e9
    print(f"DNN {CHOSEN_NET} epoch, {rows} rows, full batch: {1e3 * epoch_s:.1f} ms, {epoch_rate:.1f} GFLOP/s")
    print(f"one {rows} x {units} x {units} float32 product: {1e3 * product_s:.2f} ms, {product_rate:.1f} GFLOP/s")
    print(f"the epoch at the product's speed: {epoch_rate / product_rate:.2f} of it; {epochs} epochs {epoch_s * epochs:.1f} s")


def _search_specs(args: argparse.Namespace) -> list[ModelSpec]:
    print(f"model search: every net batch {SWEEP_BATCH_SIZE}, lr {DEFAULT_LEARNING_RATE:g}")
    return paper_models(epochs=args.epochs, sweep_folds=args.sweep_folds or None, quick=args.quick)


def _chosen_specs(args: argparse.Namespace) -> list[ModelSpec]:
    """Linear, forest and the chosen net with the DNNCalibrator defaults (full batch)."""
    epochs = min(args.epochs, 30) if args.quick else args.epochs
    default = DNNCalibrator()
    print(f"chosen net with DNNCalibrator defaults: batch {default.batch_size}, lr {default.learning_rate:g}, {epochs} epochs")
    specs = [spec for spec in paper_models() if spec.name in ("Lin_EA", "Lin_Q", "RFs_t100_dN")]
    return specs + [ModelSpec(CHOSEN_NET, "DNN", epochs=epochs, make=lambda seed: DNNCalibrator(epochs=epochs, seed=seed, progress=False))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--folds", type=int, default=10, help="CV folds (default: %(default)s)")
    parser.add_argument("--epochs", type=int, default=PAPER_EPOCHS, help="epochs of every net (default: %(default)s)")
    parser.add_argument(
        "--sweep-folds",
        type=int,
        default=SWEEP_FOLDS,
        help="folds scored for the 23 other nets with --search; 0 for all (default: %(default)s)",
    )
    parser.add_argument("--search", action="store_true", help="run the paper's full model search")
    parser.add_argument("--plot", default="model_search.png", help="figure path with --search")
    parser.add_argument("--quick", action="store_true", help="smoke run (few epochs and folds)")
    parser.add_argument("--throughput", action="store_true", help="only time an epoch against a plain matrix product (300 epochs)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--split",
        choices=("contiguous", "shuffled"),
        default="shuffled",
        help="contiguous folds in row order, as the authors ran it, or shuffled ones (default: %(default)s)",
    )
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"folds": (2, 1000), "epochs": (1, MAX_EPOCHS), "seed": (0, 2**31 - 1)})
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)  # the network trains on one thread; --throughput's plain product too, like with like
    X, y = load_paper_phase1()
    print(f"authors' Phase I data: {X.shape[0]} rows; torch {torch.__version__}, {torch.get_num_threads()} thread(s)")
    if args.throughput:
        _throughput(X, y, epochs=300)
        return

    specs = _search_specs(args) if args.search else _chosen_specs(args)
    wall, cpu = time.perf_counter(), time.process_time()
    results = run_search(X, y, models=specs, folds=args.folds, seed=args.seed, quick=args.quick, shuffle=args.split == "shuffled")
    print(format_table(results))
    print(
        "the paper (mm^2): "
        + ", ".join(f"{name} {mm2}" for name, mm2 in paper.SEARCH_MM2.items())
        + "; the authors' code on these rows: "
        + ", ".join(f"{name} {mm2}" for name, mm2 in paper.AUTHORS_CV_MM2.items())
    )
    print(f"search time: wall {time.perf_counter() - wall:.0f} s, CPU {time.process_time() - cpu:.0f} s")
    if args.search:
        plot_search(results, args.plot)
        print(f"figure: {args.plot}")

    epochs = min(args.epochs, 30) if args.quick else args.epochs
    wall, cpu = _time_training(X, y, epochs)
    print(f"DNN {CHOSEN_NET} training with defaults, {X.shape[0]} rows x {epochs} epochs: wall {wall:.1f} s, CPU {cpu:.1f} s")


if __name__ == "__main__":
    main()
