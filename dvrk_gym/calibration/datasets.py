"""The authors' real data (Seita et al., ICRA 2018), in SI units.

The package ships the cleaned Phase I data set of the paper's code release (1939 rows, MIT
licence, see ``dvrk_gym/data/seita2018_phase1/README.md``; its provenance is in
:mod:`dvrk_gym.paper`), and the records of the runs that measured the paper's calibration
table with the Phase II corrections of the same days
(``dvrk_gym/data/seita2018_table_runs/README.md``). Phase I is in millimetres and degrees on
disk; every function here returns metres and radians.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from importlib import resources

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.records import parse_npy, read_npz_arrays

__all__ = ["MAX_PACKAGED_BYTES", "PACKAGED_SHA256", "PaperTableRuns", "load_paper_phase1", "load_paper_table_runs"]

_DATA_PACKAGE = "dvrk_gym"
_MM_TO_M = 1e-3
MAX_PACKAGED_BYTES = 2**20
"""The largest packaged data file read, bytes (they are 47 to 135 kB)."""
PACKAGED_SHA256 = {
    "X_train.npy": "f41564b20af4aaa957b76bc778fff2c237530c92de7291cdfe233ebe29252e30",
    "y_train.npy": "334883b4b1c7576d37c7676d32e84d467d2aee55889e600a52cc99ed54e8418b",
    "table_runs.npz": "2a38eb8f143eda3bb6c1db7559cc10b50fa510d8830b2da2257d87c5f9e302c3",
}
"""The SHA-256 of each packaged data file as released: a changed file is refused, so a
figure compared with the real robot is always compared with the authors' rows."""


def _read_packaged(folder: tuple[str, ...], name: str) -> bytes:
    """A packaged data file's bytes, if it is at most :data:`MAX_PACKAGED_BYTES` and as released.

    Raises:
        ValueError: larger, or another SHA-256 than :data:`PACKAGED_SHA256` holds.
    """
    resource = resources.files(_DATA_PACKAGE)
    for part in (*folder, name):
        resource = resource.joinpath(part)
    with resource.open("rb") as stream:
        data = stream.read(MAX_PACKAGED_BYTES + 1)
    where = "/".join((_DATA_PACKAGE, *folder, name))
    if len(data) > MAX_PACKAGED_BYTES:
        raise ValueError(f"the packaged data file {where} is larger than {MAX_PACKAGED_BYTES:,} bytes; reinstall dvrk_gym")
    digest = hashlib.sha256(data).hexdigest()
    if digest != PACKAGED_SHA256[name]:
        raise ValueError(
            f"the packaged data file {where} is not the one released (SHA-256 {digest}, expected {PACKAGED_SHA256[name]}); "
            "reinstall dvrk_gym"
        )
    return data


def _load_array(name: str) -> np.ndarray:
    where = "/".join((_DATA_PACKAGE, *paper.REAL_PHASE1_PACKAGE_DIR, name))
    array = parse_npy(where, _read_packaged(paper.REAL_PHASE1_PACKAGE_DIR, name), kinds="f")
    if not np.isfinite(array).all():
        raise ValueError(f"the packaged data file {where} holds values that are not finite")
    return array


def load_paper_phase1() -> tuple[np.ndarray, np.ndarray]:
    """Load the authors' Phase I data: camera pose in, reported base position out.

    Returns:
        X: (1939, 6) float64: camera-frame position (cx, cy, cz) of the red marker in metres
            (left camera of the stereo pair), then the robot's reported yaw, pitch, roll in
            radians (dVRK/tfx intrinsic ZYX; roll wraps at +-pi).
        y: (1939, 3) float64: the robot's reported base-frame position (bx, by, bz) in
            metres (origin at the remote centre of motion).

    Raises:
        ValueError: If the packaged files are not those released, or do not hold finite
            floats of the documented shapes.
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


@dataclass(frozen=True)
class PaperTableRuns:
    """The real runs of the paper's calibration table, and the Phase II pushes of the same days.

    Touches (630: method x setting x 35 circles, the table's setting order
    :data:`dvrk_gym.paper.CALIBRATION_SETTINGS`):

    Attributes:
        method: (630,) "RBT", "DNN" or "DNN+RF".
        setting: (630,) index into the table's six settings.
        circle_px: (630, 2) the circle's centre in the left image (u, v), pixels.
        end_effector_px: (630, 2) the centre of the box a person drew around the end effector
            after the move, pixels; the table's error is its distance from ``circle_px``.
        sent: (630, 3) where the robot was sent (the prediction, its height clipped as
            :data:`dvrk_gym.paper.TABLE_CLIPPED` says and lifted by
            :data:`dvrk_gym.paper.TABLE_LIFT_MM`), base frame, m.
        reported: (630, 3) where the robot reported itself after the move, m.
        sent_rotation: (630, 3) the commanded yaw, pitch, roll, rad.
        push_yaw: (350,) the yaw of each Phase II push, rad.
        push_round: (350,) 0: the pushes of the network's and DNN+RF's day; 1: the rigid body's.
        push_predicted: (350, 3) the network's prediction for the circle, m.
        push_before, push_after: (350, 3) the reported position before and after a person
            pushed the jaws onto the circle, m.
    """

    method: np.ndarray
    setting: np.ndarray
    circle_px: np.ndarray
    end_effector_px: np.ndarray
    sent: np.ndarray
    reported: np.ndarray
    sent_rotation: np.ndarray
    push_yaw: np.ndarray
    push_round: np.ndarray
    push_predicted: np.ndarray
    push_before: np.ndarray
    push_after: np.ndarray

    @property
    def pixel_error(self) -> np.ndarray:
        """(630,) the table's error of each touch, pixels."""
        return np.linalg.norm(self.end_effector_px - self.circle_px, axis=1)


def load_paper_table_runs() -> PaperTableRuns:
    """Load the authors' records of their calibration table's runs (metres, radians, pixels).

    Raises:
        ValueError: If the packaged file does not hold the documented arrays and shapes.
    """
    where = "/".join((_DATA_PACKAGE, *paper.REAL_TABLE_PACKAGE_DIR, "table_runs.npz"))
    arrays = read_npz_arrays(_read_packaged(paper.REAL_TABLE_PACKAGE_DIR, "table_runs.npz"), where=where, kinds="fiuU")
    touches, pushes = paper.REAL_TABLE_TOUCHES, paper.REAL_TABLE_PUSHES
    shapes = {
        "touch_method": (touches,), "touch_setting": (touches,), "touch_circle_px": (touches, 2),
        "touch_end_effector_px": (touches, 2), "touch_sent_m": (touches, 3), "touch_reported_m": (touches, 3),
        "touch_sent_rotation_deg": (touches, 3), "push_yaw_deg": (pushes,), "push_round": (pushes,), "push_predicted_m": (pushes, 3),
        "push_before_m": (pushes, 3), "push_after_m": (pushes, 3),
    }  # fmt: skip
    wrong = {
        name: arrays[name].shape if name in arrays else None
        for name, shape in shapes.items()
        if name not in arrays or arrays[name].shape != shape
    }
    if wrong:
        raise ValueError(f"packaged table runs have unexpected arrays {wrong}; expected shapes {shapes}")
    methods, settings, rounds = (
        set(arrays["touch_method"].astype(str)),
        set(arrays["touch_setting"].tolist()),
        set(arrays["push_round"].tolist()),
    )
    numbers = [name for name, array in arrays.items() if array.dtype.kind == "f" and not np.isfinite(array).all()]
    if (
        methods != set(paper.METHOD_LABELS.values())
        or not settings <= set(range(len(paper.CALIBRATION_SETTINGS)))
        or not rounds <= {0, 1}
        or numbers
    ):
        raise ValueError(
            f"packaged table runs hold methods {sorted(methods)}, settings {sorted(settings)}, push rounds {sorted(rounds)}"
            f"{f' and non-finite {numbers}' if numbers else ''}; expected {sorted(paper.METHOD_LABELS.values())}, 0-5, 0-1"
        )
    return PaperTableRuns(
        method=arrays["touch_method"].astype(str),
        setting=arrays["touch_setting"].astype(np.int64),
        circle_px=arrays["touch_circle_px"].astype(np.float64),
        end_effector_px=arrays["touch_end_effector_px"].astype(np.float64),
        sent=arrays["touch_sent_m"].astype(np.float64),
        reported=arrays["touch_reported_m"].astype(np.float64),
        sent_rotation=np.deg2rad(arrays["touch_sent_rotation_deg"]),
        push_yaw=np.deg2rad(arrays["push_yaw_deg"]),
        push_round=arrays["push_round"].astype(np.int64),
        push_predicted=arrays["push_predicted_m"].astype(np.float64),
        push_before=arrays["push_before_m"].astype(np.float64),
        push_after=arrays["push_after_m"].astype(np.float64),
    )
