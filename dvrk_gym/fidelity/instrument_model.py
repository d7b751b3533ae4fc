"""The simulator's instrument as a function of its parameters: what the camera sees for each real row.

For every row of the authors' Phase I data the robot reported a base position and an
orientation; the nominal inverse kinematics gives the joint commands behind them
(:func:`real_commands`). Given a parameter vector (:data:`PARAMETERS`), :func:`predict_pixels`
runs those commands in collection order through the simulator's own cable model
(:class:`~dvrk_gym.sim.robot.cables.CableModel`, so hysteresis sees the rows' history), puts
the red tape on the true wrist, and looks at it through a camera pose, giving the pixels the
authors' detector would have reported: left (u, v) and the disparity ``d`` (pixels; the
rows give back exactly these: :func:`real_pixels`). :mod:`dvrk_gym.fidelity.identify` fits
the parameters to the rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_gym import paper
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.bias import NOMINAL_WRIST_COUPLING, BiasConfig, Instrument
from dvrk_gym.sim.robot.cables import CableModel

__all__ = [
    "Parameter",
    "PARAMETERS",
    "PARAMETER_NAMES",
    "STRETCH_REFERENCE_RAD",
    "real_commands",
    "real_pixels",
    "pixels_of_camera_points",
    "cable_model",
    "camera_pose",
    "true_joints",
    "tape_positions",
    "marker_positions",
    "camera_points",
    "predict_camera_points",
    "predict_pixels",
    "initial_vector",
]

_DEG = np.pi / 180.0
STRETCH_REFERENCE_RAD = 1.0 * _DEG
"""The outer stretch amplitude the fit's gains are relative to, rad (gain 1 = 1 degree)."""


@dataclass(frozen=True)
class Parameter:
    """One fitted parameter.

    Attributes:
        name: its name in :data:`PARAMETER_NAMES`.
        unit: its SI unit.
        prior_sd: sd of a zero-mean Gaussian prior (same unit); None for no prior. The
            priors say what a plausible instrument is where the rows alone cannot tell
            (homing good to about a degree, a millimetre along the shaft).
        initial: the starting value of the fit (same unit); the camera's comes from
            :func:`initial_vector`.
    """

    name: str
    unit: str
    prior_sd: float | None = None
    initial: float = 0.0


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("camera_rotvec_x", "rad"),
    Parameter("camera_rotvec_y", "rad"),
    Parameter("camera_rotvec_z", "rad"),
    Parameter("camera_x", "m"),
    Parameter("camera_y", "m"),
    Parameter("camera_z", "m"),
    Parameter("log_depth_scale", "1"),
    Parameter("marker_x", "m"),
    Parameter("marker_y", "m", initial=0.0075),
    Parameter("marker_z", "m", initial=-0.0013),
    Parameter("homing_insertion", "m", prior_sd=1.0e-3),
    Parameter("homing_roll", "rad", prior_sd=1.0 * _DEG),
    Parameter("homing_wrist_pitch", "rad", prior_sd=1.0 * _DEG),
    Parameter("outer_stretch_yaw", "rad", prior_sd=2.0 * _DEG),
    Parameter("outer_stretch_pitch", "rad", prior_sd=2.0 * _DEG),
    Parameter("wrist_stretch", "1", prior_sd=0.1),
    Parameter("backlash_outer", "rad", prior_sd=1.0 * _DEG, initial=0.2 * _DEG),
    Parameter("backlash_wrist", "rad", prior_sd=1.0 * _DEG, initial=0.2 * _DEG),
)
"""The fitted parameters, in the order of a parameter vector. Camera: T_base_leftcam as a
rotation vector and the camera's position (base frame), and the log of the factor by which
the authors' triangulation scales true camera-frame positions (their baseline against the
true one). Marker: the red tape's centre in the wrist-yaw frame. Homing offsets of the
joints the rows can tell apart from a camera move (outer yaw and pitch offsets turn the
whole arm about the RCM, which the camera pose absorbs; a wrist-yaw offset turns the tape
about the jaw pivot, which the tape's position absorbs). Outer stretch: the signed
amplitude A of ``A tanh((q - q_unloaded) / s)`` per outer joint
(:func:`dvrk_gym.sim.robot.cables.outer_stretch`). Wrist stretch: the signed compliance k of
:func:`~dvrk_gym.sim.robot.cables.wrist_stretch`. Backlash: the hysteresis gaps of the outer
and the wrist joints (their absolute values are used)."""
PARAMETER_NAMES: tuple[str, ...] = tuple(p.name for p in PARAMETERS)
_INDEX = {name: i for i, name in enumerate(PARAMETER_NAMES)}


def real_commands(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The nominal joint commands (N, 6) behind the rows' reported poses, rad / m.

    Each row's pose is ``kinematics.pose_from_euler(y, yaw, pitch, roll)``; the inverse
    kinematics takes the previous row's joints as reference, so roll stays continuous
    along the collection as the controller kept it.
    """
    commands = []
    previous: np.ndarray | None = None
    for position, euler in zip(y, X[:, 3:]):
        previous = ik.inverse_kinematics(kin.pose_from_euler(position, *euler), q_ref=previous)
        commands.append(previous)
    return np.array(commands)


def pixels_of_camera_points(points: np.ndarray) -> np.ndarray:
    """Left (u, v) and the disparity d of camera-frame points (N, 3) m, with the authors' cameras, (N, 3) px."""
    focal = paper.ENDOSCOPE_FOCAL_PX
    cx, cy = paper.ENDOSCOPE_PRINCIPAL_POINT_PX
    x, y, z = points.T
    return np.stack([focal * x / z + cx, focal * y / z + cy, focal * paper.ENDOSCOPE_BASELINE_M / z], axis=1)


def real_pixels(X: np.ndarray) -> np.ndarray:
    """The detections behind the rows' camera positions: left (u, v) and disparity, (N, 3) px.

    The authors triangulated with ROS's stereo model from their camera files, so these are
    exact: u and v come out as whole pixels (to 1e-8 px), and d as the length of a vector
    of whole pixels.
    """
    return pixels_of_camera_points(X[:, :3])


def _value(theta: np.ndarray, name: str) -> float:
    return float(theta[_INDEX[name]])


def cable_model(theta: np.ndarray) -> CableModel:
    """The cable model of a parameter vector: its stretch, homing and backlash (no noise)."""
    stretch = np.array([_value(theta, "outer_stretch_yaw"), _value(theta, "outer_stretch_pitch")])
    wrist = _value(theta, "wrist_stretch")
    config = BiasConfig(
        outer_stretch_rad=STRETCH_REFERENCE_RAD,
        wrist_stretch=abs(wrist),
        backlash_outer_rad=abs(_value(theta, "backlash_outer")),
        backlash_wrist_rad=abs(_value(theta, "backlash_wrist")),
    )
    offsets = np.array(
        [0.0, 0.0, _value(theta, "homing_insertion"), _value(theta, "homing_roll"), _value(theta, "homing_wrist_pitch"), 0.0]
    )
    instrument = Instrument(
        homing_offsets=offsets,
        true_dh=kin.PSM_DH,
        wrist_coupling=NOMINAL_WRIST_COUPLING * (1.0 if wrist >= 0 else -1.0),
        outer_gains=stretch / STRETCH_REFERENCE_RAD,
    )
    return CableModel(config, instrument=instrument)


def camera_pose(theta: np.ndarray) -> tuple[np.ndarray, float]:
    """T_base_leftcam (4x4, metres) and the triangulation's depth scale of a parameter vector."""
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(theta[0:3]).as_matrix()
    pose[:3, 3] = theta[3:6]
    return pose, float(np.exp(_value(theta, "log_depth_scale")))


def _wrist_yaw_frames(q: np.ndarray) -> np.ndarray:
    """Wrist-yaw frames (N, 4, 4) of joints q (N, 6) on the nominal table: link_frames(q)[5], batched."""
    frames = np.tile(np.eye(4), (len(q), 1, 1))
    for i, row in enumerate(kin.PSM_DH):
        theta = row.theta_offset_rad + (0.0 if row.prismatic else q[:, i])
        d = row.d_offset_m + (q[:, i] if row.prismatic else 0.0)
        ca, sa = np.cos(row.alpha_rad), np.sin(row.alpha_rad)
        ct, st = np.cos(theta) * np.ones(len(q)), np.sin(theta) * np.ones(len(q))
        link = np.zeros((len(q), 4, 4))
        link[:, 0, :] = np.stack([ct, -st, 0 * ct, row.a_m + 0 * ct], axis=1)
        link[:, 1, :] = np.stack([st * ca, ct * ca, -sa + 0 * ct, -sa * d + 0 * ct], axis=1)
        link[:, 2, :] = np.stack([st * sa, ct * sa, ca + 0 * ct, ca * d + 0 * ct], axis=1)
        link[:, 3, 3] = 1.0
        frames = frames @ link
    return frames


def true_joints(theta: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """The true joints (N, 6) rad / m behind each command, in order: the cable model of ``theta``
    run over the commands, so its backlash sees their history."""
    model = cable_model(theta)
    return np.array([model.true_joints(q) for q in commands])


def tape_positions(theta: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Where the tape of ``theta`` is for true joints ``q_true`` (N, 6), (N, 3) base frame, metres."""
    frames = _wrist_yaw_frames(q_true)
    offset = np.array([_value(theta, name) for name in ("marker_x", "marker_y", "marker_z")])
    return frames[:, :3, :3] @ offset + frames[:, :3, 3]


def marker_positions(theta: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """Where the tape really is for each command, in order, (N, 3) base frame, metres."""
    return tape_positions(theta, true_joints(theta, commands))


def camera_points(theta: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Base-frame positions (N, 3) m as the authors' triangulation with the camera of ``theta`` gives them, (N, 3) m."""
    pose, scale = camera_pose(theta)
    return scale * (positions - pose[:3, 3]) @ pose[:3, :3]


def predict_camera_points(theta: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """The camera-frame positions (N, 3) m the authors' triangulation would give, without noise."""
    return camera_points(theta, marker_positions(theta, commands))


def predict_pixels(theta: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """Left (u, v) and disparity (N, 3) px for each command, in order, without noise."""
    return pixels_of_camera_points(predict_camera_points(theta, commands))


def initial_vector(camera: np.ndarray) -> np.ndarray:
    """The fit's starting vector: each parameter's ``initial`` and the camera pose ``camera`` (4x4)."""
    theta = np.array([p.initial for p in PARAMETERS])
    theta[0:3] = Rotation.from_matrix(camera[:3, :3]).as_rotvec()
    theta[3:6] = camera[:3, 3]
    return theta
