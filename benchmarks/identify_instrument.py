"""Identify the paper's instrument from the authors' 1939 real Phase I rows, and check it on held-out rows.

Fits the simulator's instrument (camera pose and depth scale, tape position, homing
offsets, cable stretch, backlash; :mod:`dvrk_gym.fidelity.instrument_model`) to the first
70% of the rows in collection order, prints the fitted values with their moving-block
bootstrap sd, and the pixel and camera-frame residuals on the training and the held-out
rows, against the camera-and-tape fit alone. Then the red-tape detector's error from the
rows' row differences, the robot's repeatability from the image-plane jitter the rest
leaves on the real rows, the reported pose's lag from how often consecutive rows report
the same position (six simulated Phase I collections, one per lag of a grid), and, with one
more, the detector's misses from the share of rows kept. The values in
:mod:`dvrk_gym.sim.identified` came from this script's output before three mends to the
identification (its module docstring); what it prints now is the candidate set out in
docs/fidelity.md ("The identification mended"). The last two steps collect on the
``paper`` preset as the package holds it: to match the candidate's own lag and misses,
write its fitted values into ``sim/identified.py`` first and run them again.

Usage:
    python benchmarks/identify_instrument.py [--bootstrap 16] [--out identified.json]

About 2 minutes for the fits, 1 per simulated Phase I (seven), plus about 30 s per
bootstrap replicate (one core).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
from pathlib import Path

import numpy as np

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.fidelity import detector_noise
from dvrk_gym.fidelity.identify import (
    CAMERA_AND_TAPE,
    bootstrap_sd,
    camera_residual_rms_mm,
    fit_parameters,
    match_miss_probability,
    model_jitter_mm,
    repeatability_from_jitter,
    residual_rms,
    split,
)
from dvrk_gym.fidelity.instrument_model import PARAMETERS, real_commands, real_pixels
from dvrk_gym.fidelity.settle_lag import match_settle_lag
from dvrk_gym.fidelity.statistics import fidelity_statistics

_DEG = np.pi / 180.0


def _display(value: float, unit: str) -> tuple[float, str]:
    """A value in the unit a report uses: mm for metres, degrees for radians."""
    if unit == "m":
        return value * 1e3, "mm"
    if unit == "rad":
        return value / _DEG, "deg"
    return value, unit


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bootstrap", type=int, default=16, help="block-bootstrap replicates for the sd (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)

    X, y = load_paper_phase1()
    commands, pixels = real_commands(X, y), real_pixels(X)
    train, test = split(len(X))
    baseline = fit_parameters(commands[train], pixels[train], free=CAMERA_AND_TAPE)
    fit = fit_parameters(commands[train], pixels[train])
    sd = bootstrap_sd(fit, commands[train], pixels[train], replicates=args.bootstrap)

    print(f"Identified instrument: {len(train)} training rows (first 70%), {len(test)} held out")
    print(f"{'parameter':22s} {'value':>10s} {'bootstrap sd':>13s}  unit")
    for parameter, value, spread in zip(PARAMETERS, fit.theta, sd):
        shown, unit = _display(value, parameter.unit)
        shown_sd, _ = _display(spread, parameter.unit)
        print(f"{parameter.name:22s} {shown:10.4f} {shown_sd:13.4f}  {unit}")
    print("(the camera_rotvec rows' sd: of each replicate's turn of the fitted camera, about its axes)")
    print(f"residual scales (u, v, disparity) px: {np.round(fit.scales, 3).tolist()}")
    results: dict[str, object] = {
        "parameters": {p.name: float(v) for p, v in zip(PARAMETERS, fit.theta)},
        "bootstrap_sd": {p.name: float(s) for p, s in zip(PARAMETERS, sd)},
        "bootstrap_replicates": args.bootstrap,
    }
    print(f"\n{'model':16s} {'rows':8s} {'u, v, d RMS (px)':22s} {'camera x, y, z RMS (mm)':24s}")
    for name, theta in (("camera and tape", baseline.theta), ("full", fit.theta)):
        for rows_name, rows in (("train", train), ("held out", test)):
            pixel_rms = residual_rms(theta, commands[rows], pixels[rows])
            camera_rms = camera_residual_rms_mm(theta, commands[rows], X[rows])
            print(f"{name:16s} {rows_name:8s} {np.array2string(pixel_rms, precision=2):22s} {np.array2string(camera_rms, precision=2)}")
            results[f"{name} {rows_name}"] = {"pixel_rms": pixel_rms.tolist(), "camera_rms_mm": camera_rms.tolist()}

    differences = detector_noise.row_differences(X)
    train_counts, test_counts = detector_noise.histogram(differences[train]), detector_noise.histogram(differences[test])
    noise = detector_noise.fit_detector_noise(train_counts)
    expected = detector_noise.row_difference_probabilities(noise) * test_counts.sum()
    print(f"\nrow differences 0..{detector_noise.MAX_ROW_DIFFERENCE_PX} px, all rows: {detector_noise.histogram(differences).tolist()}")
    print(f"share over 2 px: {np.mean(differences > 2):.3f}")
    print(
        f"detector noise (train): core {noise.core_px:.3f} px, outlier {noise.outlier_px:.3f} px, "
        f"outlier probability {noise.outlier_probability:.3f}; disparity noise {detector_noise.disparity_noise_px(noise):.2f} px RMS"
    )
    print(f"held out: observed {test_counts.tolist()}, expected {np.round(expected, 1).tolist()}")
    print(f"held out chi-square p = {detector_noise.held_out_pvalue(noise, test_counts):.2g}")

    real = fidelity_statistics(X, y, cross_validation=False)
    view_jitter, plane_jitter = model_jitter_mm(fit.theta, commands, X, y)
    detector_mm = detector_noise.plane_noise_mm(noise, X[:, :3])
    repeatability = repeatability_from_jitter(real.image_plane_jitter_mm, plane_jitter, detector_mm)
    print(
        f"\nimage-plane jitter per axis (mm): real rows {real.image_plane_jitter_mm:.3f}, fitted model alone on them {plane_jitter:.3f}, "
        f"detector {detector_mm:.3f} (left {real.image_plane_jitter_mm**2 - plane_jitter**2 - detector_mm**2:+.3f} mm^2): "
        f"repeatability {repeatability * 1e3:.3f} mm RMS across the shaft"
    )
    print(f"view-axis jitter (mm): real rows {real.view_axis_jitter_mm:.3f}, fitted model alone on them {view_jitter:.3f}")
    lag = match_settle_lag()
    print(f"\nsame-position share of consecutive rows: real {lag.real_share:.4f}")
    for value, share, correlation in zip(lag.lags, lag.sim_shares, lag.sim_pitch_autocorrelations):
        print(f"  simulated Phase I, settle lag {value:.2f}: share {share:.4f}, pitch autocorrelation {correlation:.3f}")
    print(f"wrist settle lag: {lag.wrist_settle_lag:.2f} (where the share first falls to the real one, linear between the lags around it)")
    miss = match_miss_probability(wrist_settle_lag=lag.wrist_settle_lag)
    print(
        f"simulated Phase I (identified instrument, no repeatability, no misses): kept share {miss.sim_kept_share:.3f} "
        f"(real {miss.real_kept_share:.3f}): detector miss probability {miss.miss_probability:.3f}; "
        f"its image-plane jitter {miss.sim_plane_jitter_mm:.3f} mm"
    )
    results.update(
        detector_noise={"core_px": noise.core_px, "outlier_px": noise.outlier_px, "outlier_probability": noise.outlier_probability},
        repeatability_m=repeatability,
        settle_lag=dataclasses.asdict(lag),
        miss=dataclasses.asdict(miss),
    )
    if args.out is not None:
        args.out.write_text(json.dumps(results, indent=2))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
