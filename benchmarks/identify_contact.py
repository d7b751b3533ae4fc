"""Identify how the paper gives way under the jaws from the authors' records of their table's runs.

Fits :func:`dvrk_gym.fidelity.contact.fit_contact` (the give and the slide of a touch sent
under the paper) to the rigid body's runs, whose touches went up to 10 mm under it, and
checks it on the networks' runs, which the fit never saw. Also prints the control: the same
slopes for the touches sent over the paper, where there is nothing to give way, and the
identified values the simulator uses (:data:`dvrk_gym.sim.identified.PAPER_CONTACT`).
Last, the rigid body's fit again with a dead zone (``--dead-zones-mm``): both lines start
that deep under the plane of the pushes, a hinge, and how well each fits says whether the
records put the give and the slide at first contact or a little under it (F: the slide's
improvement over the straight line, one parameter, in units of its residual variance; the
best of several dead zones is a choice made on the same touches, so its F overstates what a
single test would say).
A few seconds:

    python benchmarks/identify_contact.py
"""

from __future__ import annotations

import argparse

import numpy as np

from dvrk_gym import paper
from dvrk_gym.calibration.datasets import PaperTableRuns, load_paper_table_runs
from dvrk_gym.fidelity.contact import FIXED_SETTINGS, MAX_DEAD_ZONE_M, ContactFit, fit_contact, height_over_pushes, pushes_of_run
from dvrk_gym.sim.identified import PAPER_CONTACT

FITS = (
    ("fit: RBT", ("RBT",)),
    ("held out: DNN", ("DNN",)),
    ("held out: DNN+RF", ("DNN+RF",)),
    ("held out: both networks", ("DNN", "DNN+RF")),
)
"""Which runs each printed fit uses: the rigid body's is the identification, the rest check it."""


def over_paper_slopes(runs: PaperTableRuns, method: str) -> tuple[float, float, float]:
    """For ``method``'s touches sent over the paper: the least-squares slopes of the image offset
    (u, v; px per mm) and of the reported-minus-sent height (mm per mm) on the height they were
    sent at over it, with a free intercept per run. Where there is no contact both are ~0."""
    heights, offsets, rises, run_ids = [], [], [], []
    for setting in range(FIXED_SETTINGS):
        mine = (runs.method == method) & (runs.setting == setting)
        height = height_over_pushes(runs.sent[mine], pushes_of_run(runs, method, setting))
        over = height >= 0.0
        heights.append(1e3 * height[over])
        offsets.append((runs.end_effector_px[mine] - runs.circle_px[mine])[over])
        rises.append(1e3 * (runs.reported[mine, 2] - runs.sent[mine, 2])[over])
        run_ids.append(np.full(int(over.sum()), setting))
    h, ids = np.concatenate(heights), np.concatenate(run_ids)
    design = np.c_[h, (ids[:, None] == np.arange(FIXED_SETTINGS)).astype(float)]
    slopes = [np.linalg.lstsq(design, target, rcond=None)[0][0] for target in (*np.concatenate(offsets).T, np.concatenate(rises))]
    return float(slopes[0]), float(slopes[1]), float(slopes[2])


def format_fit(name: str, fit: ContactFit) -> str:
    slide, se = fit.slide_per_depth, fit.slide_se
    return (
        f"  {name:<26s}{fit.touches:>5d} touches ({fit.touches_under:>3d} under)   slide x {slide[0]:+.3f} ({se[0]:.3f})"
        f"  y {slide[1]:+.3f} ({se[1]:.3f}) m/m, {np.hypot(*slide):.2f} mm per mm   give {fit.give:.3f} ({fit.give_se:.3f})"
    )


def dead_zone_lines(runs: PaperTableRuns, dead_zones_mm: list[float]) -> list[str]:
    """The rigid body's fit at each dead zone (mm): slide, give, residuals, and F against none."""
    straight = fit_contact(runs, ("RBT",))
    equations = 2 * straight.touches
    unknowns = 2 + 2 * FIXED_SETTINGS
    lines = []
    for dead_zone in dead_zones_mm:
        fit = fit_contact(runs, ("RBT",), dead_zone_m=1e-3 * dead_zone)
        rss, rss_straight = equations * fit.slide_rms_px**2, equations * straight.slide_rms_px**2
        f_statistic = (rss_straight - rss) / (rss / (equations - unknowns - 1))
        lines.append(
            f"  dead zone {dead_zone:4.2f} mm: slide {np.hypot(*fit.slide_per_depth):.2f} mm per mm"
            f" ({fit.slide_per_depth[0]:+.3f}, {fit.slide_per_depth[1]:+.3f}), give {fit.give:.3f},"
            f" residuals {fit.slide_rms_px:.2f} px / {1e3 * fit.give_rms_m:.3f} mm, F {f_statistic:+.1f}"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--dead-zones-mm",
        type=float,
        nargs="+",
        default=[0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0],
        help="dead zones to fit the rigid body's runs with, mm (default: %(default)s)",
    )
    args = parser.parse_args()
    if any(not 0.0 <= d <= 1e3 * MAX_DEAD_ZONE_M for d in args.dead_zones_mm):
        parser.error(f"--dead-zones-mm must lie in [0, {1e3 * MAX_DEAD_ZONE_M:g}], got {args.dead_zones_mm}")
    runs = load_paper_table_runs()
    print("touches sent under the jaws pushed onto the paper that day (the fixed yaws), least squares with an intercept per run")
    print("(standard errors in brackets):")
    fits = {name: fit_contact(runs, methods) for name, methods in FITS}
    for name, fit in fits.items():
        print(format_fit(name, fit))
    print("control, the touches sent over the paper (no contact): slopes on the height sent over it")
    for method in ("RBT", "DNN", "DNN+RF"):
        u, v, rise = over_paper_slopes(runs, method)
        print(f"  {method:<26s}image u {u:+.2f} px/mm  v {v:+.2f} px/mm   reported minus sent {rise:+.3f} mm/mm")
    identified = fits["fit: RBT"]
    per_mm = paper.PX_PER_MM * np.hypot(*identified.slide_per_depth)
    print(
        f"(under the paper, the rigid body's slide is {per_mm:.1f} px per mm of depth in the image; the networks' offsets go with"
        " their heights over the paper too, where nothing slides, so their fits under it mix that in)"
    )
    print(
        f"identified (dvrk_gym.sim.identified.PAPER_CONTACT): slide {PAPER_CONTACT.slide_per_depth} m/m, give {PAPER_CONTACT.give};"
        f" this fit rounds to ({identified.slide_per_depth[0]:.3f}, {identified.slide_per_depth[1]:.3f}), {identified.give:.3f}"
    )
    print("the rigid body's fit with a dead zone (both lines start that deep under the pushes; the simulator's has none):")
    for line in dead_zone_lines(runs, args.dead_zones_mm):
        print(line)


if __name__ == "__main__":
    main()
