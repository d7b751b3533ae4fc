"""How far, and how learnably, a cable model misses over the paper's workspace.

Random reachable moves through the paper's Phase I workspace and rotation ranges, one
after another (so hysteresis runs on), and what is left of the tip error after one rigid
fit per paper yaw (what the paper's rigid-body calibration leaves, about 4.5 mm under the
``paper`` preset) and after a smooth cubic error model (about 0.9 mm: hysteresis and
noise), and the hysteresis gap between opposite approaches. :func:`bias_statistics`
gathers them; all lengths are in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation
from sklearn.preprocessing import PolynomialFeatures

from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.cables import CableModel, play_radii

__all__ = [
    "BiasSamples",
    "sample_paper_commands",
    "sample_bias",
    "rigid_fit_residuals",
    "per_yaw_rigid_residuals",
    "smooth_fit_residuals",
    "hysteresis_gaps",
    "bias_statistics",
    "WORKSPACE_X_M",
    "WORKSPACE_Y_M",
    "WORKSPACE_Z_M",
    "APPROACH_DELTA",
]

_N_JOINTS = 6
_DEG = np.pi / 180.0

# The paper's Phase I workspace (base frame, m); its rotation ranges are in kinematics.
WORKSPACE_X_M = (0.005, 0.075)
WORKSPACE_Y_M = (0.005, 0.075)
WORKSPACE_Z_M = (-0.164, -0.154)
# Approach distance for the hysteresis gap: beyond the widest play of the presets, so
# each approach ends on its branch of the loop.
APPROACH_DELTA = np.array([2.0 * _DEG, 2.0 * _DEG, 2.0e-3, 5.0 * _DEG, 5.0 * _DEG, 5.0 * _DEG])
_GAP_SAMPLES = 200
_SMOOTH_DEGREE = 3


@dataclass(frozen=True)
class BiasSamples:
    """Moves through the paper's workspace, in the order they were made.

    Attributes:
        q_cmd: (n, 6) joint commands, rad / m.
        euler: (n, 3) reported (yaw, pitch, roll), rad: the commanded ones unless the
            wrist settles short of its commands (``BiasConfig.wrist_settle_lag``).
        reported: (n, 3) reported touch points (from the measured joints), m.
        true: (n, 3) true touch points, m.
        yaw_group: (n,) index into PAPER_YAWS_RAD of the nearest paper yaw.
    """

    q_cmd: np.ndarray
    euler: np.ndarray
    reported: np.ndarray
    true: np.ndarray
    yaw_group: np.ndarray


def sample_paper_commands(rng: np.random.Generator, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Random reachable commands over the paper's workspace and rotation ranges.

    Returns:
        (q_cmd (m, 6) rad / m, euler (m, 3) rad) with m <= n_samples: the rare poses the
        nominal IK cannot reach are skipped.
    """
    low = [WORKSPACE_X_M[0], WORKSPACE_Y_M[0], WORKSPACE_Z_M[0]]
    high = [WORKSPACE_X_M[1], WORKSPACE_Y_M[1], WORKSPACE_Z_M[1]]
    positions = rng.uniform(low, high, (n_samples, 3))
    ranges = np.array([kin.PAPER_YAW_RANGE_RAD, kin.PAPER_PITCH_RANGE_RAD, kin.PAPER_ROLL_RANGE_RAD])
    eulers = rng.uniform(ranges[:, 0], ranges[:, 1], (n_samples, 3))
    commands, kept = [], []
    for position, euler in zip(positions, eulers):
        try:
            commands.append(ik.inverse_kinematics(kin.pose_from_euler(position, *euler)))
        except ik.UnreachablePoseError:
            continue
        kept.append(euler)
    return np.array(commands).reshape(-1, _N_JOINTS), np.array(kept).reshape(-1, 3)


def sample_bias(model: CableModel, rng: np.random.Generator, n_samples: int = 2000) -> BiasSamples:
    """Move the model through random paper-workspace commands, one after another.

    The hysteresis state runs on from move to move (each sample is approached from the
    previous one) and each move gets its noise from rng; the model's state is restored
    afterwards. The reported pose is the measured joints' (the command's, unless the wrist
    settles short of it), as the robot would report it.
    """
    q_cmd, euler = sample_paper_commands(rng, n_samples)
    saved = model.get_state()
    model.reset(q_cmd[0])
    true, measured = [], []
    for q in q_cmd:
        true.append(kin.touch_point(model.true_joints(q, rng), model.true_dh))
        measured.append(model.measured_joints(q))  # a row of q_cmd, or a copy of the motors
    model.set_state(saved)
    reported = np.array([kin.touch_point(q) for q in measured])
    if model.config.wrist_settle_lag > 0.0:
        euler = np.array([kin.euler_from_pose(kin.forward_kinematics(q)) for q in measured]).reshape(-1, 3)
    yaw_group = np.argmin(np.abs(euler[:, :1] - kin.PAPER_YAWS_RAD), axis=1)
    return BiasSamples(q_cmd, euler, reported, np.array(true), yaw_group)


def rigid_fit_residuals(reported: np.ndarray, true: np.ndarray) -> np.ndarray:
    """true minus the best rigid transform (Kabsch) of reported onto true, (n, 3) m."""
    reported_mean, true_mean = reported.mean(axis=0), true.mean(axis=0)
    rotation, _ = Rotation.align_vectors(true - true_mean, reported - reported_mean)
    return true - (rotation.apply(reported - reported_mean) + true_mean)


def per_yaw_rigid_residuals(samples: BiasSamples) -> np.ndarray:
    """Residuals (n, 3) m after one rigid fit per paper yaw group (the paper's RBT)."""
    residuals = np.zeros_like(samples.true)
    for group in np.unique(samples.yaw_group):
        mask = samples.yaw_group == group
        residuals[mask] = rigid_fit_residuals(samples.reported[mask], samples.true[mask])
    return residuals


def smooth_fit_residuals(samples: BiasSamples) -> np.ndarray:
    """Out-of-sample residuals (n, 3) m of a cubic polynomial error model.

    The error (true - reported) is regressed on (reported position, yaw, pitch, roll) by
    least squares on one half of the samples and evaluated on the other half, and vice
    versa: what a smooth calibration can learn, leaving hysteresis and noise.
    """
    features = np.column_stack([samples.reported, samples.euler])
    features = (features - features.mean(axis=0)) / features.std(axis=0)
    design = PolynomialFeatures(_SMOOTH_DEGREE).fit_transform(features)
    errors = samples.true - samples.reported
    halves = np.arange(len(errors)) % 2 == 0
    residuals = np.empty_like(errors)
    for train in (halves, ~halves):
        coefficients = np.linalg.lstsq(design[train], errors[train], rcond=None)[0]
        residuals[~train] = errors[~train] - design[~train] @ coefficients
    return residuals


def hysteresis_gaps(model: CableModel, q_cmd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip distance between approaching each command from below and from above.

    Args:
        model: The cable model (its state is restored afterwards).
        q_cmd: (n, 6) commands.

    Returns:
        (all-joint gaps (n,) m: every joint approaches from -delta vs +delta at once;
        per-joint gaps (n, 6) m: one joint at a time), noiseless.
    """
    saved = model.get_state()
    delta = np.maximum(APPROACH_DELTA, 2.5 * play_radii(model.config).max(axis=0))
    directions = np.vstack([np.ones(_N_JOINTS), np.eye(_N_JOINTS)])
    gaps = np.empty((len(q_cmd), len(directions)))
    for i, q in enumerate(q_cmd):
        for k, direction in enumerate(directions):
            tips = []
            for side in (-1.0, 1.0):
                model.reset(q + side * direction * delta)
                tips.append(kin.touch_point(model.true_joints(q), model.true_dh))
            gaps[i, k] = np.linalg.norm(tips[1] - tips[0])
    model.set_state(saved)
    return gaps[:, 0], gaps[:, 1:]


def bias_statistics(model: CableModel, rng: np.random.Generator, n_samples: int = 2000) -> dict:
    """How far, and how learnably, the model misses over the paper's workspace.

    Args:
        model: The cable model; its hysteresis state is left as it was.
        rng: Source of the sampled poses and of the per-move noise.
        n_samples: Number of poses drawn (unreachable ones are skipped).

    Returns:
        Dict with (all lengths in metres): ``n_samples``; ``raw_mean_m`` (mean tip error
        norm); ``rigid_mean_m`` (after one rigid fit per paper yaw) and
        ``rigid_mean_by_yaw_m`` ((5,), per paper yaw -90..90 deg); ``smooth_mean_m``
        (after the cubic error model, out of sample); ``hysteresis_gap_m`` and
        ``hysteresis_gap_min_m`` (mean and minimum all-joint gap) and
        ``hysteresis_gap_by_joint_m`` ((6,), mean one-joint gaps).
    """
    samples = sample_bias(model, rng, n_samples)
    rigid = np.linalg.norm(per_yaw_rigid_residuals(samples), axis=1)
    by_yaw = np.array(
        [rigid[samples.yaw_group == g].mean() if np.any(samples.yaw_group == g) else np.nan for g in range(len(kin.PAPER_YAWS_RAD))]
    )
    all_gaps, joint_gaps = hysteresis_gaps(model, samples.q_cmd[:_GAP_SAMPLES])
    return {
        "n_samples": len(samples.q_cmd),
        "raw_mean_m": float(np.linalg.norm(samples.true - samples.reported, axis=1).mean()),
        "rigid_mean_m": float(rigid.mean()),
        "rigid_mean_by_yaw_m": by_yaw,
        "smooth_mean_m": float(np.linalg.norm(smooth_fit_residuals(samples), axis=1).mean()),
        "hysteresis_gap_m": float(all_gaps.mean()),
        "hysteresis_gap_min_m": float(all_gaps.min()),
        "hysteresis_gap_by_joint_m": joint_gaps.mean(axis=0),
    }
