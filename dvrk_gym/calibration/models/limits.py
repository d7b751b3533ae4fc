"""The DNN calibrator's bounds, importable without torch: the command line checks ``--epochs``
against them before any work (importing :mod:`~dvrk_gym.calibration.models.dnn` loads
torch, scikit-learn and skops, several seconds, which a refused flag should not wait for)."""

from __future__ import annotations

__all__ = ["MAX_BATCH_SIZE", "MAX_EPOCHS", "MAX_HIDDEN_LAYERS", "MAX_PARAMETERS", "MAX_UNITS"]

MAX_HIDDEN_LAYERS = 16
"""The most hidden layers a network has."""
MAX_UNITS = 4096
"""The most units a hidden layer has."""
MAX_PARAMETERS = 2**25
"""The largest network built, weights and biases (128 MiB in float32); the paper's 3 x 300 has 183,303."""
MAX_EPOCHS = 10**7
"""The most training epochs."""
MAX_BATCH_SIZE = 2**24
"""The largest mini-batch, rows."""
