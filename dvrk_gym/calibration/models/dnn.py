"""The paper's Phase I network: an MLP from camera position and angles to base position.

Inputs are encoded as position plus sine and cosine of each angle, then standardised;
outputs are centred and divided by one common scale, so the training loss is the squared
L2 distance in (scaled) metres, the paper's loss. Training is Adam on shuffled mini-batches,
in float32 on the CPU, with every random draw from a ``torch.Generator`` seeded by ``seed``.
Training and prediction run on one torch thread whatever the caller's count
(:func:`~dvrk_gym.utils.torch_threads.torch_threads`): how many threads split a matrix
product changes its last bits, and the chaotic training carries them to different weights
(on the paper's 1939 rows, 2 threads ended at a training loss 0.0020, 1 thread at 0.0036),
so ``dvrk-gym calibrate``, ``reproduce`` and ``sweep`` would otherwise train different
networks from the same data and seed. One thread costs nothing here (30 s either way for
the paper's 3 x 300 net on 2 cores). The same seed and data then give bit-identical weights
on one CPU; another CPU may still differ (MKL picks its kernels by instruction set, and
``MKL_CBWR=COMPATIBLE``, which would pin them, trains 3.8 times slower: ``docs/calibration.md``, *The
network's figures depend on the machine's arithmetic*).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from dvrk_gym import paper
from dvrk_gym.calibration.models.features import EULER_FEATURES, calibrator_layout, check_inputs, check_targets, encode_euler
from dvrk_gym.calibration.models.serialization import ModelParts, SavableModel, require_array, require_names
from dvrk_gym.utils.checks import check_bool, check_choice, check_float, check_int
from dvrk_gym.utils.torch_threads import torch_threads

__all__ = ["ACTIVATIONS", "DEFAULT_BATCH_SIZE", "DEFAULT_LEARNING_RATE", "DNNCalibrator"]

_LOGGER = logging.getLogger(__name__)

ACTIVATIONS: dict[str, type[nn.Module]] = {"relu": nn.ReLU, "sigmoid": nn.Sigmoid, "tanh": nn.Tanh}
# Chosen by measurement on the authors' 1939 rows (one CPU thread, 3 x 300 ReLU, 1000
# epochs): one full batch per epoch is the fastest (the cost is the matrix products, so
# fewer, larger steps only shed per-step overhead; batch 256 costs about 1.3 times as
# much) and on two CV folds also the most accurate: 1.14 mm^2 against 1.35-1.46 for
# batches of 256-1024; learning rate 3e-3 gave 1.25. Larger data sets get mini-batches.
# The default rate is nevertheless 3e-3: with 1e-3, the 1000 full-batch steps sometimes
# stop short on simulated Phase I data (training residual 1.31 mm against 0.41 mm at 3e-3
# on the same 1,881 rows), and the real-data CV stays well inside its 2.2 mm^2 bound.
DEFAULT_BATCH_SIZE = 2048
"""Rows per gradient step: the authors' 1939 rows (and simulated Phase I) are one full batch."""
DEFAULT_LEARNING_RATE = 3e-3
"""Adam's learning rate."""
_INPUT_FEATURES = 9
_OUTPUTS = 3
_PROGRESS_EVERY_EPOCHS = 25
MAX_HIDDEN_LAYERS = 16
"""The most hidden layers a network may have (the paper's has 3)."""
MAX_UNITS = 4096
"""The most units a hidden layer may have (the paper's have 300)."""
MAX_PARAMETERS = 2**25
"""The largest network built, weights and biases (128 MiB in float32); the paper's 3 x 300 has 183,303."""
MAX_EPOCHS = 10**7
"""The most epochs a training may ask for (the paper's: 1000)."""
MAX_BATCH_SIZE = 2**24
"""The largest batch a training may ask for, rows (a batch never holds more than the data)."""


def network_parameters(hidden_layers: int, units: int) -> int:
    """The weights and biases of an MLP with ``hidden_layers`` layers of ``units`` (9 inputs, 3 outputs)."""
    widths = [_INPUT_FEATURES] + [units] * hidden_layers + [_OUTPUTS]
    return sum((fan_in + 1) * fan_out for fan_in, fan_out in zip(widths[:-1], widths[1:]))


def _build_network(hidden_layers: int, units: int, activation: str) -> nn.Sequential:
    """An uninitialised MLP (parameters allocated, values unset)."""
    layers: list[nn.Module] = []
    width = _INPUT_FEATURES
    for _ in range(hidden_layers):
        # Built on the meta device so construction draws nothing from torch's global RNG; in
        # float32 whatever torch's default dtype (the inputs are float32).
        layers += [nn.Linear(width, units, device="meta", dtype=torch.float32), ACTIVATIONS[activation]()]
        width = units
    layers.append(nn.Linear(width, _OUTPUTS, device="meta", dtype=torch.float32))
    return nn.Sequential(*layers).to_empty(device="cpu")


def _initialise(network: nn.Sequential, generator: torch.Generator) -> None:
    """PyTorch's default ``nn.Linear`` initialisation, drawn from ``generator``."""
    with torch.no_grad():
        for layer in network:
            if isinstance(layer, nn.Linear):
                bound = 1.0 / math.sqrt(layer.in_features)
                layer.weight.uniform_(-bound, bound, generator=generator)
                layer.bias.uniform_(-bound, bound, generator=generator)


class DNNCalibrator(SavableModel):
    """Phase I: an MLP mapping (position, yaw, pitch, roll) to base position.

    Args:
        hidden_layers: Number of hidden layers (paper's choice: 3).
        units: Units per hidden layer (paper: 300).
        activation: ``"relu"``, ``"sigmoid"`` or ``"tanh"``.
        epochs: Passes over the training data (paper: 1000).
        batch_size: Rows per Adam step. The default, 2048, is one full batch per epoch on
            the paper's 1939 rows: fastest, and as accurate as smaller batches for the
            3 x 300 ReLU net; small or sigmoid nets need more steps (the model search uses 256).
        learning_rate: Adam's step size.
        seed: Seeds the weight initialisation and the shuffling.
        progress: Show a tqdm bar over epochs.
    """

    KIND = "dnn_calibrator"

    def __init__(
        self,
        *,
        hidden_layers: int = paper.DNN_HIDDEN_LAYERS,
        units: int = paper.DNN_UNITS,
        activation: str = paper.DNN_ACTIVATION,
        epochs: int = paper.DNN_EPOCHS,
        batch_size: int = DEFAULT_BATCH_SIZE,
        learning_rate: float = DEFAULT_LEARNING_RATE,
        seed: int = 0,
        progress: bool = True,
    ) -> None:
        self.hidden_layers = check_int("hidden_layers", hidden_layers, 1, MAX_HIDDEN_LAYERS)
        self.units = check_int("units", units, 1, MAX_UNITS)
        self.activation = check_choice("activation", activation, sorted(ACTIVATIONS))
        self.epochs = check_int("epochs", epochs, 1, MAX_EPOCHS)
        self.batch_size = check_int("batch_size", batch_size, 1, MAX_BATCH_SIZE)
        self.learning_rate = check_float("learning_rate", learning_rate, low=0.0, high=1.0, low_open=True)
        self.seed = check_int("seed", seed, 0, 2**63 - 1)
        self.progress = check_bool("progress", progress)
        parameters = network_parameters(self.hidden_layers, self.units)
        if parameters > MAX_PARAMETERS:
            raise ValueError(
                f"a {self.hidden_layers} x {self.units} network has {parameters:,} parameters; at most {MAX_PARAMETERS:,} are allowed"
            )
        self.network_: nn.Sequential | None = None
        self.x_mean_: np.ndarray | None = None  # (9,) encoded-input mean
        self.x_scale_: np.ndarray | None = None  # (9,) encoded-input standard deviation
        self.y_mean_: np.ndarray | None = None  # (3,) base-position mean, metres
        self.y_scale_: np.ndarray | None = None  # (3,) output scale, metres (all equal)
        self.loss_history_: np.ndarray | None = None  # (epochs,) mean scaled training loss

    def _params(self) -> dict[str, Any]:
        return {
            "hidden_layers": self.hidden_layers,
            "units": self.units,
            "activation": self.activation,
            "epochs": self.epochs,
            "batch_size": self.batch_size,
            "learning_rate": self.learning_rate,
            "seed": self.seed,
        }

    def fit(self, X: np.ndarray, y: np.ndarray) -> DNNCalibrator:
        """Train on inputs X (N, 6: metres, radians) and base positions y (N, 3, metres).

        Raises:
            ValueError: bad inputs or targets (:func:`check_inputs`, :func:`check_targets`), or
                ones that spread beyond what a float holds; a refused fit leaves the model as it was.
        """
        X = check_inputs(X)
        y = check_targets(y, X.shape[0])
        features = encode_euler(X)
        x_mean = features.mean(axis=0)
        # Constant features (e.g. one yaw only) are left unscaled instead of divided by zero.
        spread = features.std(axis=0)
        x_scale = np.where(spread > 0.0, spread, 1.0)
        y_mean = y.mean(axis=0)
        # One scale for all three outputs keeps the loss an (isotropic) squared L2 distance.
        with np.errstate(over="ignore"):  # an overflow is refused just below, by name
            output_spread = float(np.sqrt(np.mean((y - y_mean) ** 2)))
        y_scale = np.full(_OUTPUTS, output_spread if output_spread > 0.0 else 1.0)
        if not (np.isfinite(x_scale).all() and np.isfinite(y_scale).all()):
            raise ValueError("the inputs or targets spread beyond what a float holds; expected metres and radians")
        self.x_mean_, self.x_scale_, self.y_mean_, self.y_scale_ = x_mean, x_scale, y_mean, y_scale
        inputs = torch.from_numpy(((features - self.x_mean_) / self.x_scale_).astype(np.float32))
        targets = torch.from_numpy(((y - self.y_mean_) / self.y_scale_).astype(np.float32))
        generator = torch.Generator().manual_seed(self.seed)
        network = _build_network(self.hidden_layers, self.units, self.activation)
        _initialise(network, generator)
        self.network_ = network
        with torch_threads(1):  # the same weights whatever the caller's thread count (module docstring)
            self.loss_history_ = self._train(network, inputs, targets, generator)
        return self

    def _train(self, network: nn.Sequential, inputs: torch.Tensor, targets: torch.Tensor, generator: torch.Generator) -> np.ndarray:
        optimizer = torch.optim.Adam(network.parameters(), lr=self.learning_rate)
        rows = inputs.shape[0]
        history = np.empty(self.epochs)
        network.train()
        bar = tqdm(
            range(self.epochs),
            desc=f"DNN {self.hidden_layers}x{self.units} {self.activation}",
            unit="epoch",
            disable=not self.progress,
            leave=False,
        )
        for epoch in bar:
            order = torch.randperm(rows, generator=generator)
            shuffled_inputs, shuffled_targets = inputs[order], targets[order]
            total = torch.zeros(())
            for start in range(0, rows, self.batch_size):
                batch = slice(start, start + self.batch_size)
                optimizer.zero_grad(set_to_none=True)
                error = network(shuffled_inputs[batch]) - shuffled_targets[batch]
                loss = error.square().sum(dim=1).mean()
                loss.backward()
                optimizer.step()
                total += loss.detach() * error.shape[0]
            history[epoch] = float(total) / rows
            if epoch % _PROGRESS_EVERY_EPOCHS == 0:
                bar.set_postfix(loss=f"{history[epoch]:.3g}")
        network.eval()
        _LOGGER.debug("trained %s: final scaled loss %.4g", self._params(), history[-1])
        return history

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Base positions (N, 3) in metres for inputs X (N, 6: metres, radians).

        Raises:
            ValueError: called before fit, bad inputs (:func:`check_inputs`), or a row whose
                features overflow the network (no finite prediction; the message names it).
        """
        if self.network_ is None:
            raise ValueError("DNNCalibrator.predict called before fit")
        features = encode_euler(check_inputs(X))
        with np.errstate(over="ignore"):  # a row beyond float32 gives no finite prediction, refused below by its index
            inputs = torch.from_numpy(((features - self.x_mean_) / self.x_scale_).astype(np.float32))
        # One thread: a row's product changes in its last bits with the count, and on 2 threads one
        # row took 203 us against 54 (entering and leaving the pin: 1-2 us).
        with torch_threads(1), torch.inference_mode():
            outputs = self.network_(inputs).numpy().astype(np.float64)
        predictions = outputs * self.y_scale_ + self.y_mean_
        if not np.isfinite(predictions).all():
            row = int(np.argwhere(~np.isfinite(predictions))[0, 0])
            raise ValueError(
                f"X row {row} ({check_inputs(X)[row].tolist()}) gives no finite prediction: its features overflow the "
                "network's float32 range; expected metres and radians near the training data's"
            )
        return predictions

    def _layer_names(self) -> list[str]:
        return [f"layer{i}" for i in range(self.hidden_layers + 1)]

    def layout(self) -> dict[str, Any]:
        """Inputs (m, rad), the network's encoded features (standardised), outputs (m)."""
        return calibrator_layout(EULER_FEATURES)

    def _export(self) -> ModelParts:
        if self.network_ is None or self.x_mean_ is None or self.x_scale_ is None or self.y_mean_ is None or self.y_scale_ is None:
            raise ValueError("DNNCalibrator.save called before fit")
        linears = [layer for layer in self.network_ if isinstance(layer, nn.Linear)]
        arrays = {"x_mean": self.x_mean_, "x_scale": self.x_scale_, "y_mean": self.y_mean_, "y_scale": self.y_scale_}
        for name, layer in zip(self._layer_names(), linears):
            arrays[f"{name}_weight"] = layer.weight.detach().numpy().copy()
            arrays[f"{name}_bias"] = layer.bias.detach().numpy().copy()
        return ModelParts(self._params(), arrays)

    @classmethod
    def _from_params(cls, params: Mapping[str, Any]) -> DNNCalibrator:
        return cls(**params, progress=False)  # checks the sizes against fixed bounds before anything is read or built

    def _load_parts(self, parts: ModelParts) -> None:
        arrays = parts.arrays
        names = self._layer_names()
        require_names(parts.estimators, set(), "estimators")
        require_names(arrays, {"x_mean", "x_scale", "y_mean", "y_scale"} | {f"{n}_{part}" for n in names for part in ("weight", "bias")})
        widths = [_INPUT_FEATURES] + [self.units] * self.hidden_layers + [_OUTPUTS]
        for name, fan_in, fan_out in zip(names, widths[:-1], widths[1:]):  # the file's arrays fit the header before it is built
            require_array(arrays, f"{name}_weight", (fan_out, fan_in), np.float32)
            require_array(arrays, f"{name}_bias", (fan_out,), np.float32)
        x_scale = require_array(arrays, "x_scale", (_INPUT_FEATURES,), np.float64)
        y_scale = require_array(arrays, "y_scale", (_OUTPUTS,), np.float64)
        smallest = np.finfo(np.float64).tiny  # a subnormal scale (1e-320) divides every input to inf
        if not (np.all(x_scale >= smallest) and np.all(y_scale >= smallest)):
            raise ValueError(f"x_scale and y_scale must be positive normal floats (at least {smallest:g})")
        network = _build_network(self.hidden_layers, self.units, self.activation)
        state = {}
        for index, name in enumerate(names):
            state[f"{2 * index}.weight"] = torch.from_numpy(arrays[f"{name}_weight"].copy())
            state[f"{2 * index}.bias"] = torch.from_numpy(arrays[f"{name}_bias"].copy())
        network.load_state_dict(state)
        network.eval()
        self.x_mean_ = require_array(arrays, "x_mean", (_INPUT_FEATURES,), np.float64)
        self.x_scale_, self.y_scale_ = x_scale, y_scale
        self.y_mean_ = require_array(arrays, "y_mean", (_OUTPUTS,), np.float64)
        self.network_ = network
