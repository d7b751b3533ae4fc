"""A wrist the cable model lacks: the wrist yaw turning with the wrist pitch. Do the real rows'
pixels ask for it, and does it change what the camera sees?

The EndoWrist's yaw cables run over the pitch pulleys, and the dVRK's controller undoes that
with a coupling matrix; an error in it turns the jaws with the wrist pitch. The cable model
has a load-dependent coupling (the wrist stretch), not this kinematic one. This script:

1. fits the identification (:func:`dvrk_gym.fidelity.identify.fit_parameters`) on its
   training rows, then again with one more parameter, ``c``: the true wrist yaw gains ``c``
   times the true wrist pitch (rad per rad). The pixel residuals (u, v, disparity RMS) on
   the training and held-out rows, ``c``, and where each fit puts the tape in the wrist-yaw
   frame (the jaws' tips are at y = 10 mm);
2. renders a simulated Phase I's recorded joints (the ``paper`` instrument, the paper's 57
   trajectories, one raw row in two, no misses) with the fitted coupling added, the tape
   where it is and moved as far towards the tips as the 3 mm strip fits: the share of seen
   rows per nearest yaw and their median pitch, against the real kept rows'.

    python benchmarks/identify_wrist_coupling.py       # under 2 min
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
from fidelity_visibility import JointRecorder, render_rows, shares_and_medians
from scipy.optimize import least_squares

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym import paper
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, collect_phase1
from dvrk_gym.fidelity import identify
from dvrk_gym.fidelity import instrument_model as model
from dvrk_gym.sim.robot import body
from dvrk_gym.sim.robot import kinematics as kin

WRIST_PITCH, WRIST_YAW = 4, 5
TAPE = slice(model.PARAMETER_NAMES.index("marker_x"), model.PARAMETER_NAMES.index("marker_x") + 3)
"""The tape's centre (x, y, z) in a parameter vector."""


def coupled(joints: np.ndarray, coupling: float) -> np.ndarray:
    """A copy of ``joints`` (N, >= 6) whose wrist yaw gains ``coupling`` times the wrist pitch (rad per rad)."""
    out = np.array(joints, dtype=float)
    out[:, WRIST_YAW] += coupling * out[:, WRIST_PITCH]
    return out


def coupled_pixels(theta: np.ndarray, coupling: float, commands: np.ndarray) -> np.ndarray:
    """Left (u, v) and disparity (N, 3) px of the instrument ``theta`` whose true wrist yaw
    gains ``coupling`` times its true wrist pitch (rad per rad)."""
    q_true = coupled(model.true_joints(theta, commands), coupling)
    return model.pixels_of_camera_points(model.camera_points(theta, model.tape_positions(theta, q_true)))


def fit_coupling(fit: identify.InstrumentFit, commands: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, float]:
    """The identification's free parameters and the coupling, fitted together from ``fit``
    (same residual scales, priors and robust loss): (theta, coupling)."""

    def residuals(values: np.ndarray) -> np.ndarray:
        theta = identify.theta_of(values[:-1], fit)
        scaled = ((coupled_pixels(theta, values[-1], commands) - pixels) / fit.scales).ravel()
        return np.concatenate([identify.huber_residuals(scaled), identify.prior_residuals(theta, fit.free)])

    # The camera's rotation as a turn of the fit's (zero at the start), as identify.refit fits it.
    result = least_squares(residuals, np.r_[identify.start_values(fit), 0.0], x_scale="jac", diff_step=1e-5)
    return identify.theta_of(result.x[:-1], fit), float(result.x[-1])


@contextlib.contextmanager
def tape_at(y_m: float) -> Iterator[None]:
    """The simulated tape centred ``y_m`` along the jaws while inside (bodies built inside carry it)."""
    original = body.MARKER
    body.MARKER = dataclasses.replace(original, offset_m=(original.offset_m[0], y_m, original.offset_m[2]))
    try:
        yield
    finally:
        body.MARKER = original


def _rms(predicted: np.ndarray, pixels: np.ndarray) -> str:
    return " / ".join(f"{v:.2f}" for v in np.sqrt(np.mean((predicted - pixels) ** 2, axis=0)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trajectories", type=int, default=paper.PHASE1_TRAJECTORIES)
    parser.add_argument("--every", type=int, default=2, help="render one raw row in this many")
    args = parser.parse_args()
    if args.trajectories < 1 or args.every < 1:
        parser.error("--trajectories and --every must be at least 1")

    real_X, real_y = load_paper_phase1()
    commands, pixels = model.real_commands(real_X, real_y), model.real_pixels(real_X)
    train, held_out = identify.split(len(commands))
    fit = identify.fit_parameters(commands[train], pixels[train])
    theta, coupling = fit_coupling(fit, commands[train], pixels[train])
    print("1. The identification's pixel residuals, u / v / disparity RMS (px), and its tape (wrist-yaw frame, mm)")
    print(f"{'fit':34s} {'training':>20s} {'held out':>20s}  tape x, y, z")
    for label, values, c in (("as identified", fit.theta, 0.0), (f"with the coupling, c = {coupling:+.3f}", theta, coupling)):
        rms = [_rms(coupled_pixels(values, c, commands[rows]), pixels[rows]) for rows in (train, held_out)]
        tape = values[TAPE] * 1e3
        print(f"{label:34s} {rms[0]:>20s} {rms[1]:>20s}  {tape[0]:.2f}, {tape[1]:.2f}, {tape[2]:.2f}")

    env = JointRecorder(gym.make("dvrk_gym/CalibrationExploration-v0", max_steps=paper.PHASE1_POSES_PER_TRAJECTORY))
    try:
        data = collect_phase1(env, PaperExplorationPolicy(seed=0), args.trajectories, seed=0, progress=False)
    finally:
        env.close()
    rows = np.arange(0, data.n_raw, args.every)
    joints = np.array(env.joints)[rows]
    tip_tape_m = kin.JAW_LENGTH_M - body.MARKER.half_extents_m[1]
    real_shares, real_medians = shares_and_medians(real_X[:, 3:6])
    print(f"\n2. Seen rows (one raw row in {args.every}, no misses) per nearest yaw -90 .. 90: share of the seen rows | median pitch (deg)")
    print(f"{'real (kept rows)':44s} {' '.join(f'{v:.2f}' for v in real_shares)} | {' '.join(f'{v:6.1f}' for v in real_medians)}")
    variants = (
        ("as identified", joints, None),
        (f"coupling {coupling:+.3f}", coupled(joints, coupling), None),
        (f"coupling {coupling:+.3f}, tape at {tip_tape_m * 1e3:.1f} mm", coupled(joints, coupling), tip_tape_m),
    )
    for label, these, tape_y in variants:
        with tape_at(tape_y) if tape_y is not None else contextlib.nullcontext():
            seen = render_rows(these)
        shares, medians = shares_and_medians(data.orientation[rows][seen])
        print(
            f"{label:44s} {' '.join(f'{v:.2f}' for v in shares)} | {' '.join(f'{v:6.1f}' for v in medians)}   seen {seen.mean():.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
