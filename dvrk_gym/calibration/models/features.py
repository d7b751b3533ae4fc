"""Input checks and encodings shared by the calibration models.

A calibration input row is ``(cx, cy, cz, yaw, pitch, roll)``: the camera-frame position in
metres and the dVRK/tfx Euler angles (intrinsic ZYX) in radians; a target row is the base
position ``(bx, by, bz)`` in metres. Angles are encoded by their sines and cosines so that
roll's wrap at +-pi (the paper's roll is drawn from [-180, -150] deg and some readings wrap
to +180) is invisible to the models.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_gym.sim.robot.kinematics import PAPER_YAWS_RAD

__all__ = [
    "EULER_FEATURES",
    "INPUT_COLUMNS",
    "OUTPUT_COLUMNS",
    "PAPER_YAWS_RAD",
    "QUATERNION_FEATURES",
    "calibrator_layout",
    "check_inputs",
    "check_targets",
    "encode_euler",
    "encode_quaternion",
    "nearest_yaw_index",
]

INPUT_COLUMNS = ("cx_m", "cy_m", "cz_m", "yaw_rad", "pitch_rad", "roll_rad")
"""A calibration input row: camera-frame position (m) and yaw, pitch, roll (rad)."""
OUTPUT_COLUMNS = ("bx_m", "by_m", "bz_m")
"""A calibration target row: base-frame position (m)."""
EULER_FEATURES = ("cx_m", "cy_m", "cz_m", "sin_yaw", "sin_pitch", "sin_roll", "cos_yaw", "cos_pitch", "cos_roll")
"""The columns of :func:`encode_euler`."""
QUATERNION_FEATURES = ("cx_m", "cy_m", "cz_m", "qx", "qy", "qz", "qw")
"""The columns of :func:`encode_quaternion`."""
# The quaternion sign is chosen on the side of this orientation (yaw 0, pitch 0, roll pi:
# the paper's tool points down), so the encoding is continuous over the whole workspace.
_QUATERNION_REFERENCE_XYZW = np.array([1.0, 0.0, 0.0, 0.0])


def calibrator_layout(features: tuple[str, ...] | None = None) -> dict[str, list[str]]:
    """A calibrator's layout for its model file: inputs, the features it computes from them (if any), outputs."""
    layout = {"inputs": list(INPUT_COLUMNS), "outputs": list(OUTPUT_COLUMNS)}
    return layout if features is None else {**layout, "features": list(features)}


MAX_POSITION_M = 1.0
"""The farthest position a calibrator takes, m: the dVRK's workspace and camera lie within
0.3 m of the base; a larger number is another unit (millimetres)."""
MAX_ANGLE_RAD = 2.0 * np.pi
"""The largest angle a calibrator takes, rad (a larger number is degrees)."""


def check_inputs(X: object, name: str = "X", columns: int = 6) -> np.ndarray:
    """Validate a 2-D array of finite numbers with a fixed number of columns.

    Args:
        X: Array-like of shape (N, columns).
        name: Name used in error messages.
        columns: Required number of columns (6 for calibration inputs).

    Returns:
        The array as float64, shape (N, columns).

    Raises:
        ValueError: If it does not hold real numbers (complex, bool, text, objects), is not
            2-D with ``columns`` columns, is empty or not finite, or its positions or angles
            are not in metres and radians (``MAX_POSITION_M``, ``MAX_ANGLE_RAD``; six
            columns: a calibrator's inputs, three: base positions, one: angles).
    """
    try:
        raw = np.asarray(X)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} is not a numeric array: {error}") from None
    if raw.dtype.kind not in "fiu":  # complex (its imaginary part dropped), bools, text and objects are not coerced
        raise ValueError(f"{name} must hold real numbers, got dtype {raw.dtype}")
    array = raw.astype(np.float64)
    if array.ndim != 2 or array.shape[1] != columns:
        raise ValueError(f"{name} has shape {array.shape}; expected (N, {columns})")
    if array.shape[0] == 0:
        raise ValueError(f"{name} has no rows; expected at least one")
    if not np.all(np.isfinite(array)):
        row = int(np.argwhere(~np.isfinite(array))[0, 0])
        raise ValueError(f"{name} row {row} is not finite ({array[row]}); expected finite values")
    _check_si_units(array, name)
    return array


def _check_si_units(array: np.ndarray, name: str) -> None:
    """Positions within ``MAX_POSITION_M`` and angles within ``MAX_ANGLE_RAD``: millimetres or
    degrees would fit a model that is silently wrong. Six columns are a calibrator's inputs
    (position, then yaw, pitch, roll), three a base position, one an angle (a yaw)."""
    positions, angles = {6: (array[:, :3], array[:, 3:]), 3: (array, None), 1: (None, array)}.get(array.shape[1], (None, None))
    if positions is not None and (position := np.abs(positions).max()) > MAX_POSITION_M:
        raise ValueError(f"{name}'s positions reach {position:.4g}; expected metres (within {MAX_POSITION_M:g} m of the origin)")
    if angles is not None and (angle := np.abs(angles).max()) > MAX_ANGLE_RAD:
        raise ValueError(f"{name}'s angles reach {angle:.4g}; expected radians (within 2 pi)")


def check_targets(y: object, rows: int, name: str = "y") -> np.ndarray:
    """Validate base positions (N, 3) in metres, with N equal to the inputs' row count."""
    array = check_inputs(y, name=name, columns=3)
    if array.shape[0] != rows:
        raise ValueError(f"{name} has {array.shape[0]} rows but the inputs have {rows}")
    return array


def encode_euler(X: np.ndarray) -> np.ndarray:
    """Position plus the sine and cosine of each angle.

    Args:
        X: (N, 6) calibration inputs (metres, radians).

    Returns:
        (N, 9): cx, cy, cz in metres, then sin(yaw), sin(pitch), sin(roll), cos(yaw),
        cos(pitch), cos(roll).
    """
    angles = X[:, 3:6]
    return np.concatenate([X[:, :3], np.sin(angles), np.cos(angles)], axis=1)


def encode_quaternion(X: np.ndarray) -> np.ndarray:
    """Position plus the orientation as a unit quaternion.

    Args:
        X: (N, 6) calibration inputs (metres, radians).

    Returns:
        (N, 7): cx, cy, cz in metres, then the quaternion (x, y, z, w) of
        Rz(yaw) Ry(pitch) Rx(roll), signed to lie on the hemisphere of a tool pointing down.
    """
    quaternions = Rotation.from_euler("ZYX", X[:, 3:6]).as_quat()
    signs = np.where(quaternions @ _QUATERNION_REFERENCE_XYZW < 0.0, -1.0, 1.0)
    return np.concatenate([X[:, :3], quaternions * signs[:, None]], axis=1)


def nearest_yaw_index(yaw_rad: object) -> np.ndarray:
    """Index of the nearest of the paper's five yaws (-90, -45, 0, 45, 90 deg).

    Distances are wrapped, so a yaw of 179 deg is 1 deg from -180 deg; ties go to the lower
    index.

    Args:
        yaw_rad: Scalar or array of yaws in radians.

    Returns:
        Integer array of the input's shape with values in 0..4 (into ``PAPER_YAWS_RAD``).
    """
    yaw = np.asarray(yaw_rad, dtype=np.float64)
    difference = np.angle(np.exp(1j * (yaw[..., None] - PAPER_YAWS_RAD)))
    return np.argmin(np.abs(difference), axis=-1)
