"""The authors' Phase I calibration data (Seita et al., ICRA 2018), in SI units.

The package ships the cleaned data set of the paper's code release (1939 rows, MIT licence,
see ``dvrk_gym/data/seita2018_phase1/README.md``; its provenance is in :mod:`dvrk_gym.paper`).
On disk it is in millimetres and degrees; every function here returns metres and radians.
"""

from __future__ import annotations

import io
from importlib import resources

import numpy as np

from dvrk_gym import paper

__all__ = ["load_paper_phase1"]

_DATA_PACKAGE = "dvrk_gym"
_MM_TO_M = 1e-3


def _load_array(name: str) -> np.ndarray:
    resource = resources.files(_DATA_PACKAGE)
    for part in (*paper.REAL_PHASE1_PACKAGE_DIR, name):
        resource = resource.joinpath(part)
    with resource.open("rb") as stream:
        return np.load(io.BytesIO(stream.read()), allow_pickle=False)


def load_paper_phase1() -> tuple[np.ndarray, np.ndarray]:
    """Load the authors' Phase I data: camera pose in, reported base position out.

    Returns:
        X: (1939, 6) float64: camera-frame position (cx, cy, cz) of the red marker in metres
            (left camera of the stereo pair), then the robot's reported yaw, pitch, roll in
            radians (dVRK/tfx intrinsic ZYX; roll wraps at +-pi).
        y: (1939, 3) float64: the robot's reported base-frame position (bx, by, bz) in
            metres (origin at the remote centre of motion).

    Raises:
        ValueError: If the packaged files do not have the documented shapes.
    """
    X_raw = _load_array("X_train.npy")
    y_raw = _load_array("y_train.npy")
    if X_raw.shape != (paper.REAL_PHASE1_ROWS, 6) or y_raw.shape != (paper.REAL_PHASE1_ROWS, 3):
        raise ValueError(
            f"packaged Phase I data has shapes X {X_raw.shape}, y {y_raw.shape}; "
            f"expected ({paper.REAL_PHASE1_ROWS}, 6) and ({paper.REAL_PHASE1_ROWS}, 3)"
        )
    X = np.empty_like(X_raw, dtype=np.float64)
    X[:, :3] = X_raw[:, :3] * _MM_TO_M
    X[:, 3:] = np.deg2rad(X_raw[:, 3:])
    return X, y_raw.astype(np.float64) * _MM_TO_M
