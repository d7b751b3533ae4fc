"""What the real Phase I rows' sequence says about the pose the dVRK reports.

The simulator reports the pose it was commanded (``World.reported_pose``: nominal FK of the
joint command). Two statistics of ``dvrk-gym fidelity`` say the real robot does not: its
consecutive rows rarely report the same position (0.03 against 0.44), and consecutive
pitches are correlated (0.27 against 0.06). This script measures, on the authors' rows:

1. How far a repeated command is reported apart. The authors' protocol returns to the
   trajectory's own orientation at every pause; within each trajectory (a run of rows whose
   reported positions move by less than 10 mm from one to the next) the rows within 3
   degrees, on every angle, of the orientation that recurs most are those returns. Their
   spread about their median is what the reported angles scatter by for one command.
2. Whether a dead band in the measured joints explains the correlation: the protocol's
   pitch commands (57 trajectories of 23 pauses, the trajectory's own pitch then three
   uniform in [-15, 25] degrees) through a play operator of half-width ``h`` (the measured
   joint stops ``h`` short of a command it approaches), 37% of rows kept at random: the
   spread of the returns and the lag-1 correlation of the kept pitches, per ``h``.

    python benchmarks/fidelity_sequence.py
"""

import numpy as np

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity.statistics import JITTER_MAX_STEP_M, lag_one_correlation

_CLUSTER_DEG = 3.0
_MIN_RETURNS = 4
_PITCH_RANGE_DEG = (-15.0, 25.0)
_KEPT_SHARE = 1939 / 5256


def return_deviations(angles_deg: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
    """(M, 3) deviation of each return to a trajectory's own orientation from their median, degrees."""
    steps = np.linalg.norm(np.diff(positions_m, axis=0), axis=1)
    edges = np.r_[0, np.flatnonzero(steps > JITTER_MAX_STEP_M) + 1, len(positions_m)]
    deviations = []
    for start, stop in zip(edges[:-1], edges[1:]):
        segment = angles_deg[start:stop]
        near = np.all(np.abs(segment[:, None, :] - segment[None, :, :]) < _CLUSTER_DEG, axis=2)
        anchor = int(np.argmax(near.sum(axis=1)))
        returns = segment[near[anchor]]
        if len(returns) >= _MIN_RETURNS:
            deviations.append(returns - np.median(returns, axis=0))
    return np.vstack(deviations)


def protocol_pitches(rng: np.random.Generator, trajectories: int = 57, pauses: int = 23) -> tuple[np.ndarray, np.ndarray]:
    """The protocol's pitch commands (degrees) and the indices of the returns to each
    trajectory's own pitch, (trajectories, pauses)."""
    commands, returns = [], []
    for _ in range(trajectories):
        own = rng.uniform(*_PITCH_RANGE_DEG)
        for _ in range(pauses):
            returns.append(len(commands))
            commands += [own, *rng.uniform(*_PITCH_RANGE_DEG, size=3)]
    return np.array(commands), np.array(returns).reshape(trajectories, pauses)


def play(commands: np.ndarray, half_width: float) -> np.ndarray:
    """A play operator: the output follows the input only when it leaves a band of +-half_width around it."""
    output, state = np.empty_like(commands), float(commands[0])
    for i, command in enumerate(commands):
        state = min(max(state, command - half_width), command + half_width)
        output[i] = state
    return output


if __name__ == "__main__":
    X, y = load_paper_phase1()
    angles = np.rad2deg(X[:, 3:])
    angles[:, 2] = np.where(angles[:, 2] > 0, angles[:, 2] - 360.0, angles[:, 2])  # roll wraps at +-180
    deviations = return_deviations(angles, y)
    rms = np.sqrt(np.mean(deviations**2, axis=0))
    print(f"real rows: {len(deviations)} returns to a trajectory's own orientation")
    print(f"  reported spread about their median, RMS (yaw, pitch, roll): {rms[0]:.2f}, {rms[1]:.2f}, {rms[2]:.2f} deg")
    print(f"  pitch lag-1 correlation of the rows: {lag_one_correlation(X[:, 4]):.2f}")
    rng = np.random.default_rng(0)
    commands, returns = protocol_pitches(rng)
    kept = rng.random(len(commands)) < _KEPT_SHARE
    print("the protocol's pitch commands through a dead band of half-width h, 37% of rows kept at random:")
    for half_width in (0.0, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0):
        measured = play(commands, half_width)
        at_returns = measured[returns]  # (trajectories, pauses): about their median, as on the real rows
        spread = np.sqrt(np.mean((at_returns - np.median(at_returns, axis=1, keepdims=True)) ** 2))
        correlation = lag_one_correlation(measured[kept])
        print(
            f"  h {half_width:3.1f} deg: spread of the returns {spread:4.2f} deg, pitch lag-1 correlation of kept rows {correlation:+.2f}"
        )
