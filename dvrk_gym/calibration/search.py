"""The paper's Phase I model search: k-fold cross-validation of nets, linear maps and forests.

The paper compares 24 networks (1-4 hidden layers x 30 or 300 units x ReLU, sigmoid, tanh),
linear regression on Euler angles and on quaternions, and random forests, by 10-fold
cross-validation of the mean squared L2 error of the predicted base position (mm^2).

Cost: 1000 epochs of the 24 nets take far more than 30 minutes on one CPU core, so by
default the sweep trains every net but the chosen one (3 x 300 ReLU) for
``SWEEP_EPOCHS`` epochs and says so in the table's caption; the chosen net keeps the
paper's 1000 epochs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterable, Protocol

import numpy as np
from matplotlib.figure import Figure
from sklearn.model_selection import KFold
from tqdm import tqdm

from dvrk_gym.calibration.dnn import DNNCalibrator
from dvrk_gym.calibration.features import check_inputs, check_targets
from dvrk_gym.calibration.forests import ForestCalibrator
from dvrk_gym.calibration.linear import LinearCalibrator

__all__ = [
    "CHOSEN_NET",
    "PAPER_EPOCHS",
    "SWEEP_EPOCHS",
    "Calibrator",
    "ModelSpec",
    "SearchResult",
    "cross_validate",
    "format_table",
    "paper_models",
    "plot_search",
    "run_search",
    "search_caption",
]

PAPER_EPOCHS = 1000
SWEEP_EPOCHS = 300
CHOSEN_NET = "DNN_u300_h3_relu"
_M2_TO_MM2 = 1e6
_QUICK_FOLDS = 3
_QUICK_EPOCHS = 30
_FAMILY_COLOURS = {"Lin": "tab:blue", "RFs": "tab:red", "DNN": "tab:olive"}
_LOG_SCALE_RATIO = 10.0  # log y axis when the largest bar is this many times the smallest


class Calibrator(Protocol):
    """Anything with ``fit(X, y)`` and ``predict(X)`` on SI calibration arrays."""

    def fit(self, X: np.ndarray, y: np.ndarray) -> "Calibrator": ...

    def predict(self, X: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class ModelSpec:
    """One candidate of the search.

    Attributes:
        name: Label in the paper's style: ``Lin_EA``, ``RFs_t100_dN``, ``DNN_u300_h3_relu``.
        family: ``"Lin"``, ``"RFs"`` or ``"DNN"`` (colours the bar chart).
        make: Builds an unfitted model from a seed.
        epochs: Training epochs for networks (None otherwise), for the caption.
    """

    name: str
    family: str
    make: Callable[[int], Calibrator]
    epochs: int | None = None


@dataclass(frozen=True)
class SearchResult:
    """Cross-validated error of one model.

    Attributes:
        name: The model's label.
        family: ``"Lin"``, ``"RFs"`` or ``"DNN"``.
        mean_mm2: Mean over folds of the per-fold mean squared L2 error, mm^2.
        std_mm2: Standard deviation over folds of that per-fold error, mm^2.
        fold_mm2: The per-fold errors, mm^2.
        epochs: Training epochs for networks, else None.
        seconds: Wall-clock time of all folds, seconds.
    """

    name: str
    family: str
    mean_mm2: float
    std_mm2: float
    fold_mm2: tuple[float, ...]
    epochs: int | None
    seconds: float


def _net(units: int, layers: int, activation: str, epochs: int) -> ModelSpec:
    return ModelSpec(
        name=f"DNN_u{units}_h{layers}_{activation}", family="DNN", epochs=epochs,
        make=lambda seed: DNNCalibrator(hidden_layers=layers, units=units, activation=activation,
                                        epochs=epochs, seed=seed, progress=False))


def _forest(trees: int, depth: int | None) -> ModelSpec:
    return ModelSpec(name=f"RFs_t{trees}_d{'N' if depth is None else depth}", family="RFs",
                     make=lambda seed: ForestCalibrator(trees=trees, max_depth=depth, seed=seed))


def paper_models(sweep_epochs: int = SWEEP_EPOCHS, chosen_epochs: int = PAPER_EPOCHS,
                 quick: bool = False) -> list[ModelSpec]:
    """The candidates of the paper's search.

    Args:
        sweep_epochs: Epochs of every net except the chosen 3 x 300 ReLU.
        chosen_epochs: Epochs of the chosen net (paper: 1000).
        quick: A handful of models (two linear, one forest, the chosen net and the paper's
            best net) with both epoch counts capped at 30, for smoke runs.

    Returns:
        Linear models, forests, then the 24 nets (units, layers, activation order).
    """
    if quick:
        sweep_epochs = min(sweep_epochs, _QUICK_EPOCHS)
        chosen_epochs = min(chosen_epochs, _QUICK_EPOCHS)
    specs = [
        ModelSpec("Lin_EA", "Lin", lambda seed: LinearCalibrator(angles="euler")),
        ModelSpec("Lin_Q", "Lin", lambda seed: LinearCalibrator(angles="quaternion")),
    ]
    specs += [_forest(trees, depth) for trees in (10, 100) for depth in (10, None)]
    for units in (30, 300):
        for layers in (1, 2, 3, 4):
            for activation in ("relu", "sigmoid", "tanh"):
                chosen = (units, layers, activation) == (300, 3, "relu")
                specs.append(_net(units, layers, activation,
                                  chosen_epochs if chosen else sweep_epochs))
    if quick:
        keep = {"Lin_EA", "Lin_Q", "RFs_t10_dN", CHOSEN_NET, "DNN_u300_h1_sigmoid"}
        specs = [spec for spec in specs if spec.name in keep]
    return specs


def _mean_squared_l2_mm2(predicted: np.ndarray, actual: np.ndarray) -> float:
    return float(np.mean(np.sum((predicted - actual) ** 2, axis=1)) * _M2_TO_MM2)


def cross_validate(make: Callable[[int], Calibrator], X: np.ndarray, y: np.ndarray,
                   folds: int = 10, seed: int = 0,
                   on_fold: Callable[[], None] | None = None) -> list[float]:
    """K-fold cross-validation error of one model.

    Args:
        make: Builds an unfitted model from a seed (called once per fold with ``seed``).
        X: (N, 6) inputs: camera position in metres, yaw, pitch, roll in radians.
        y: (N, 3) base positions in metres.
        folds: Number of folds (shuffled ``KFold``, ``random_state=seed``).
        seed: Seeds both the split and the models.
        on_fold: Called after each fold (e.g. to advance a progress bar).

    Returns:
        Per-fold mean squared L2 error of the held-out predictions, in mm^2.
    """
    X = check_inputs(X)
    y = check_targets(y, X.shape[0])
    errors = []
    for train, test in KFold(n_splits=folds, shuffle=True, random_state=seed).split(X):
        model = make(seed).fit(X[train], y[train])
        errors.append(_mean_squared_l2_mm2(model.predict(X[test]), y[test]))
        if on_fold is not None:
            on_fold()
    return errors


def run_search(X: np.ndarray, y: np.ndarray, models: Iterable[ModelSpec] | None = None,
               folds: int = 10, seed: int = 0, quick: bool = False,
               progress: bool = True) -> list[SearchResult]:
    """Cross-validate every candidate, with a progress bar over (model, fold).

    Args:
        X: (N, 6) inputs (metres, radians).
        y: (N, 3) base positions (metres).
        models: Candidates; default :func:`paper_models` (``quick`` passed on).
        folds: Number of folds (paper: 10; ``quick`` caps it at 3).
        seed: Seeds the split and every model.
        quick: A smoke run: few models, few epochs, 3 folds.
        progress: Show the tqdm bar.

    Returns:
        One :class:`SearchResult` per model, in the given order.
    """
    specs = list(models) if models is not None else paper_models(quick=quick)
    if quick:
        folds = min(folds, _QUICK_FOLDS)
    results = []
    with tqdm(total=len(specs) * folds, desc="model search", unit="fold",
              disable=not progress) as bar:
        for spec in specs:
            bar.set_postfix_str(spec.name)
            start = time.perf_counter()
            errors = cross_validate(spec.make, X, y, folds=folds, seed=seed,
                                    on_fold=lambda: bar.update(1))
            results.append(SearchResult(
                name=spec.name, family=spec.family, mean_mm2=float(np.mean(errors)),
                std_mm2=float(np.std(errors)), fold_mm2=tuple(errors), epochs=spec.epochs,
                seconds=time.perf_counter() - start))
    return results


def search_caption(results: Iterable[SearchResult]) -> str:
    """One line stating the folds and the epochs each network was trained for."""
    results = list(results)
    folds = {len(result.fold_mm2) for result in results}
    epochs: dict[int, list[str]] = {}
    for result in results:
        if result.epochs is not None:
            epochs.setdefault(result.epochs, []).append(result.name)
    parts = [f"{'/'.join(map(str, sorted(folds)))}-fold CV, mean squared L2 error (mm^2)"]
    if len(epochs) == 1:
        parts.append(f"nets trained {next(iter(epochs))} epochs")
    elif epochs:
        parts += [f"{', '.join(names) if len(names) <= 2 else f'{len(names)} nets'} "
                  f"trained {count} epochs" for count, names in sorted(epochs.items())]
    return "; ".join(parts)


def format_table(results: Iterable[SearchResult], caption: str | None = None) -> str:
    """A plain-text table: name, mean and std of the per-fold error (mm^2), epochs, time.

    Args:
        results: Search results.
        caption: First line; default :func:`search_caption`.
    """
    results = list(results)
    caption = search_caption(results) if caption is None else caption
    width = max([len("model")] + [len(result.name) for result in results])
    lines = [caption, f"{'model':<{width}}  {'mean mm^2':>9}  {'std mm^2':>8}  "
                      f"{'epochs':>6}  {'time s':>7}"]
    for r in results:
        epochs = "-" if r.epochs is None else str(r.epochs)
        lines.append(f"{r.name:<{width}}  {r.mean_mm2:9.3f}  {r.std_mm2:8.3f}  "
                     f"{epochs:>6}  {r.seconds:7.1f}")
    return "\n".join(lines)


def plot_search(results: Iterable[SearchResult], path: str, caption: str | None = None) -> None:
    """Save the paper's bar chart: mean squared L2 error per model with 1-sd error bars.

    The y axis is logarithmic when the bars span more than a factor of ten.

    Args:
        results: Search results (one bar each, in order).
        path: Output PNG path.
        caption: Title; default :func:`search_caption`.
    """
    results = list(results)
    means = np.array([r.mean_mm2 for r in results])
    stds = np.array([r.std_mm2 for r in results])
    figure = Figure(figsize=(max(6.0, 0.45 * len(results) + 2.0), 5.0), layout="constrained")
    axes = figure.subplots()
    positions = np.arange(len(results))
    axes.bar(positions, means, yerr=stds, capsize=3, alpha=0.8, error_kw={"ecolor": "0.3"},
             color=[_FAMILY_COLOURS.get(r.family, "tab:gray") for r in results])
    axes.set_xticks(positions, [r.name for r in results], rotation=75, fontsize=8)
    axes.set_ylabel("mean squared L2 error (mm$^2$)")
    if means.size and means.min() > 0 and means.max() / means.min() > _LOG_SCALE_RATIO:
        axes.set_yscale("log")
    axes.set_title(search_caption(results) if caption is None else caption, fontsize=9)
    axes.grid(axis="y", alpha=0.3)
    figure.savefig(path, dpi=150)
