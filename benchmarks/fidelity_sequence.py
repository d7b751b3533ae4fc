"""What the real Phase I rows' sequence says about the pose the dVRK reports.

A simulator whose encoders report the command (``wrist_settle_lag=0``) reports the pose it
was commanded (``World.reported_pose``: nominal FK of the measured joints). Two statistics
of ``dvrk-gym fidelity`` say the real robot does not: its consecutive rows rarely report the
same position (0.03 against 0.52 without the lag), and consecutive pitches are correlated
(0.27 against 0.05). This script measured, on the authors' rows, what led to the ``paper``
preset's settle lag (:data:`dvrk_gym.sim.identified.WRIST_SETTLE_LAG`):

1. How far a repeated command is reported apart. The authors' protocol returns to the
   trajectory's own orientation at every pause; within each trajectory (a run of rows whose
   reported positions move by less than 10 mm from one to the next) the rows within 3
   degrees, on every angle, of the orientation that recurs most are those returns. Their
   spread about their median is what the reported angles scatter by for one command.
2. Which model of the reported pitch gives both that spread and the real rows' pitch
   correlation at lags 1-4. The protocol's pitch commands (57 trajectories of 23 pauses:
   the trajectory's own pitch, three uniform in [-15, 25] degrees, and an unrecorded
   return to its own pitch before the arm moves on), 37% of rows kept at random, through
   (a) a dead band: a play operator of half-width ``h`` (the measured joint stops ``h``
   short of a command it approaches); (b) a first-order lag: each move leaves a fraction
   ``alpha`` of the previous error, ``reported = command + alpha (previous reported -
   command)``. The best ``alpha`` matches the spread and the four correlations in least
   squares (three seeds of the toy protocol each).
3. How far the arm moved between pauses (:func:`pause_steps`): from each row at a
   trajectory's own orientation to the next row, 1 to 4 rows on, within 4 degrees of it on
   every angle (the next pause's first row), the distance in x and y. The paper's text says
   about a millimetre, the authors' collector 2 mm (:data:`dvrk_gym.paper.PHASE1_STEP_M`);
   ``--phase1 FILE`` prints the same for a simulated collection (a calibration folder's
   ``phase1.npz``, its kept rows).

    python benchmarks/fidelity_sequence.py [--phase1 DIR/phase1.npz]
"""

import argparse
from pathlib import Path

import numpy as np

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import Phase1Data
from dvrk_gym.fidelity.statistics import JITTER_MAX_STEP_M, lag_one_correlation
from dvrk_gym.sim.robot.cables import play_update

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


def pause_steps(angles_rad: np.ndarray, positions_m: np.ndarray, max_rows: int = 4, tolerance_deg: float = 4.0) -> np.ndarray:
    """(M, 2): for each row followed, 1 to ``max_rows`` rows on, by one within ``tolerance_deg``
    on every angle (the first such), how many rows on and the distance between the two in x
    and y, metres. At the protocol's pauses the trajectory's own orientation comes first, so
    such a pair is one pause and the next (or, rarely, two random draws alike).

    Args:
        angles_rad: (N, 3) yaw, pitch, roll of the rows in collection order, radians.
        positions_m: (N, 3) their reported positions, metres.
    """
    angles_rad, positions_m = np.asarray(angles_rad, dtype=float), np.asarray(positions_m, dtype=float)
    if angles_rad.ndim != 2 or angles_rad.shape[1] != 3 or positions_m.shape != angles_rad.shape:
        raise ValueError(f"expected (N, 3) angles and positions, got {angles_rad.shape} and {positions_m.shape}")
    tolerance = np.deg2rad(tolerance_deg)
    pairs = []
    for row in range(len(angles_rad)):
        for later in range(row + 1, min(len(angles_rad), row + max_rows + 1)):
            difference = np.angle(np.exp(1j * (angles_rad[later] - angles_rad[row])))  # roll wraps at +-180 degrees
            if np.all(np.abs(difference) < tolerance):
                pairs.append((later - row, float(np.linalg.norm(positions_m[later, :2] - positions_m[row, :2]))))
                break
    return np.array(pairs, dtype=float).reshape(-1, 2)


def print_pause_steps(name: str, angles_rad: np.ndarray, positions_m: np.ndarray) -> None:
    """The median of :func:`pause_steps` for each number of rows on, mm."""
    steps = pause_steps(angles_rad, positions_m)
    medians = [
        f"{1e3 * np.median(steps[steps[:, 0] == rows, 1]):.2f} ({int(np.sum(steps[:, 0] == rows))})"
        if np.any(steps[:, 0] == rows)
        else "- (0)"
        for rows in range(1, 5)
    ]
    print(f"{name}: the step between pauses, median mm (pairs) for the next pause 1 / 2 / 3 / 4 rows on: {' / '.join(medians)}")


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


def lagged(commands: np.ndarray, alpha: float, returns: np.ndarray) -> np.ndarray:
    """Each move keeps ``alpha`` of the previous error; an unrecorded return move to the
    trajectory's own pitch precedes every pause's first row but the trajectory's first."""
    output, state = np.empty_like(commands), float(commands[0])
    first_rows = set(returns[:, 1:].ravel().tolist())
    for i, command in enumerate(commands):
        if i in first_rows:  # the return to the own pitch, at the end of the last pause
            state = command + alpha * (state - command)
        state = command + alpha * (state - command)
        output[i] = state
    return output


def correlations(values: np.ndarray, lags: tuple[int, ...] = (1, 2, 3, 4)) -> np.ndarray:
    """Pearson correlations of the sequence with itself ``lag`` rows later."""
    return np.array([np.corrcoef(values[:-lag], values[lag:])[0, 1] for lag in lags])


def return_spread(measured: np.ndarray, returns: np.ndarray) -> float:
    """RMS of the returns about their median per trajectory, degrees (as on the real rows)."""
    at_returns = measured[returns]
    return float(np.sqrt(np.mean((at_returns - np.median(at_returns, axis=1, keepdims=True)) ** 2)))


def play(commands: np.ndarray, half_width: float) -> np.ndarray:
    """The simulator's play operator (:func:`~dvrk_gym.sim.robot.cables.play_update`) run
    over a sequence: the output follows the input only when it leaves a band of +-half_width around it."""
    output, state = np.empty_like(commands), np.array(commands[:1])
    for i, command in enumerate(commands):
        state = play_update(state, command, half_width)
        output[i] = state[0]
    return output


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--phase1", type=Path, default=None, help="a simulated collection's phase1.npz, for its step between pauses")
    args = parser.parse_args()
    X, y = load_paper_phase1()
    print_pause_steps("real rows", X[:, 3:], y)
    if args.phase1 is not None:
        simulated = Phase1Data.load(args.phase1).cleaned()
        print_pause_steps(f"simulated kept rows ({args.phase1})", simulated.orientation, simulated.reported_position)
    angles = np.rad2deg(X[:, 3:])
    angles[:, 2] = np.where(angles[:, 2] > 0, angles[:, 2] - 360.0, angles[:, 2])  # roll wraps at +-180
    deviations = return_deviations(angles, y)
    rms = np.sqrt(np.mean(deviations**2, axis=0))
    print(f"real rows: {len(deviations)} returns to a trajectory's own orientation")
    print(f"  reported spread about their median, RMS (yaw, pitch, roll): {rms[0]:.2f}, {rms[1]:.2f}, {rms[2]:.2f} deg")
    yaw, pitch, roll = (lag_one_correlation(angles[:, axis]) for axis in range(3))
    print(f"  lag-1 correlation of consecutive rows, yaw / pitch / roll: {yaw:.2f} / {pitch:.2f} / {roll:.2f}")
    real_correlations = correlations(X[:, 4])
    print(f"  pitch correlation at lags 1-4: {np.array2string(real_correlations, precision=2)}")
    toys = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        commands, returns = protocol_pitches(rng)
        toys.append((commands, returns, rng.random(len(commands)) < _KEPT_SHARE))
    print("(a) the protocol's pitch commands through a dead band of half-width h, 37% of rows kept at random (seed 0):")
    commands, returns, kept = toys[0]
    for half_width in (0.0, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0):
        measured = play(commands, half_width)
        lag_one = lag_one_correlation(measured[kept])
        spread = return_spread(measured, returns)
        print(f"  h {half_width:3.1f} deg: spread of the returns {spread:4.2f} deg, lag-1 correlation {lag_one:+.2f}")
    print("(b) a first-order lag, each move keeping alpha of the previous error (mean of 3 seeds):")
    target = np.r_[rms[1], real_correlations]
    scale = np.r_[rms[1], np.ones(4) * 0.1]  # the spread relative, the correlations in tenths
    best = (np.inf, 0.0)
    for alpha in np.round(np.arange(0.0, 0.61, 0.05), 2):
        figures = np.mean([np.r_[return_spread(lagged(c, alpha, r), r), correlations(lagged(c, alpha, r)[k])] for c, r, k in toys], axis=0)
        misfit = float(np.sum(((figures - target) / scale) ** 2))
        best = min(best, (misfit, float(alpha)))
        print(f"  alpha {alpha:4.2f}: spread {figures[0]:4.2f} deg, correlations at lags 1-4 {np.array2string(figures[1:], precision=2)}")
    print(f"best alpha {best[1]:.2f} (least squares on the spread, relative, and the four correlations)")
