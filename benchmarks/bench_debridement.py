"""Debridement: the paper's trial table per calibrator and fragment, and the wall time per trial.

Run: python benchmarks/bench_debridement.py --calibration DIR  [--trials 15]
DIR is a calibration run folder made by ``dvrk-gym calibrate --out DIR`` (or ``evaluate``).
Targets (issue 6; the paper, 15 trials x 8 fragments per cell): DNN+RF success >= 88 % on
seeds and >= 95 % on raisins with type A rare; DNN alone clearly worse, mostly through A;
B on seeds only, C on raisins only; about 7.2 s simulated per fragment, the phases in the
paper's proportions; one 8-fragment trial in at most 30 s wall on one core.

``--what-if-physics-step S`` and ``--what-if-coarse-only`` run the table on a changed
simulation (``benchmarks/bench_pick_parts.py`` says what each changes and how fast a pick
then is): what issue 18's 10 picks/s would cost in the table.

``--contact rigid`` runs the picks on a paper that does not give way (the jaws stall on the
floor over it, where they are), as Debridement-v0 did before its picks met GridTouch-v0's
paper; ``--grip-depth-mm D`` lowers the jaws D mm under the target instead of the authors' 2
(their ``--z_offset``), to see how far the slide at that depth costs picks.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from bench_pick_parts import add_what_if_arguments, apply_what_ifs

import dvrk_gym  # noqa: F401
from dvrk_gym import paper
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.policy import CalibratedPolicy
from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.envs.debridement_config import DEFAULT_PICK_TIMING
from dvrk_gym.envs.picks import PHASES
from dvrk_gym.evaluation.trials import run_debridement, totals, unpicked_note
from dvrk_gym.paper import DEBRIDEMENT_PHASE_S as PAPER_PHASE_S
from dvrk_gym.sim.table.contact import CONTACTS, DEFAULT_CONTACT


def bench_cell(
    folder: Path, calibrator_name: str, fragment: str, trials: int, seed: int, resolution: tuple[int, int], **env_kwargs: object
) -> dict:
    """Run one cell of the table as ``dvrk-gym debride`` does (``run_debridement``); returns its
    totals and the wall seconds per trial (the env's construction included). ``env_kwargs`` go to
    ``gym.make`` (``contact``, ``timing``)."""
    calibrator, settings = load_calibrator(folder, calibrator_name)
    contact = str(env_kwargs.pop("contact", DEFAULT_CONTACT))
    start = time.perf_counter()
    results = run_debridement(
        CalibratedPolicy(calibrator, target=fragment_target),
        n_trials=trials,
        seed=seed,
        fragment=fragment,
        bias=settings["bias"],
        bias_seed=int(settings["bias_seed"]),
        camera_resolution=resolution,
        contact=contact,
        env_kwargs=env_kwargs,
    )
    wall = (time.perf_counter() - start) / trials
    return {**totals(results), "wall_s_per_trial": wall, "rows": [",".join(t.outcomes) for t in results]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--calibration", type=Path, default=Path("dvrk_gym_out/calibration"), help="calibration run folder (default: %(default)s)"
    )
    parser.add_argument("--trials", type=int, default=15, help="trials per cell (the paper: %(default)s)")
    parser.add_argument(
        "--calibrators", nargs="+", default=["dnn", "dnn+rf"], choices=sorted(paper.METHOD_LABELS), help="calibrators (default: dnn dnn+rf)"
    )
    parser.add_argument(
        "--fragments",
        nargs="+",
        default=["pumpkin_seed", "raisin"],
        choices=["pumpkin_seed", "raisin"],
        help="fragment kinds (default: both)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the first trial (default: %(default)s)")
    parser.add_argument(
        "--resolution", type=int, nargs=2, default=(1920, 1080), metavar=("W", "H"), help="endoscope image size (default: 1920 1080)"
    )
    parser.add_argument("--rows", action="store_true", help="also print every trial's outcome string")
    parser.add_argument("--contact", choices=sorted(CONTACTS), default="compliant", help="the paper under the picks (default: %(default)s)")
    default_depth_mm = 1e3 * DEFAULT_PICK_TIMING.grip_depth_m
    parser.add_argument(
        "--grip-depth-mm",
        type=float,
        default=default_depth_mm,
        help="how far under the target the jaws are lowered, mm (default: %(default)s)",
    )
    add_what_if_arguments(parser)
    args = parser.parse_args()
    what_if = apply_what_ifs(parser, args)
    if what_if:
        print(what_if)
    if not 0.0 <= args.grip_depth_mm <= 100.0:
        parser.error(f"--grip-depth-mm must be in [0, 100], got {args.grip_depth_mm}")
    timing = dataclasses.replace(DEFAULT_PICK_TIMING, grip_depth_m=1e-3 * args.grip_depth_mm)
    env_kwargs = {"contact": args.contact, "timing": timing}
    print(f"paper: {args.contact}; the jaws lowered {args.grip_depth_mm:g} mm under the target")
    header = f"{'fragment':<14}{'calibrator':<10}{'success':>15}{'A':>5}{'B':>5}{'C':>5}{'s/fragment':>12}{'wall s/trial':>14}{'paper':>26}"
    print(header)
    phase_lines = []
    for fragment in args.fragments:
        for name in args.calibrators:
            cell = bench_cell(args.calibration, name, fragment, args.trials, args.seed, tuple(args.resolution), **env_kwargs)
            reference = paper.DEBRIDEMENT_RESULTS.get((name, fragment))
            picks = paper.DEBRIDEMENT_PICKS_PER_CELL
            paper_text = f"{reference['success']}/{picks} A{reference['A']} B{reference['B']} C{reference['C']}" if reference else "-"
            success = f"{cell['success']}/{cell['picks']} ({100 * cell['success'] / max(cell['picks'], 1):.0f}%)"
            print(
                f"{fragment:<14}{paper.METHOD_LABELS[name]:<10}{success:>15}{cell['A']:>5}{cell['B']:>5}{cell['C']:>5}"
                f"{cell['time_per_fragment_s']:>12.2f}{cell['wall_s_per_trial']:>14.1f}{paper_text:>26}",
                flush=True,
            )
            if args.rows:
                print("    " + " | ".join(cell["rows"]))
            if cell["sim_errors"]:
                print(f"    {cell['sim_errors']} trial(s) ended with a physics failure")
            if unpicked_note(cell):
                print(f"    {unpicked_note(cell)}")
            phase_lines.append(f"{fragment:<14}{paper.METHOD_LABELS[name]:<10}" + "".join(f"{cell['phase_s'][p]:>16.2f}" for p in PHASES))
    print()
    print(f"{'phases, s':<24}" + "".join(f"{p:>16}" for p in PHASES))
    for line in phase_lines:
        print(line)
    print(f"{'paper (25 fps frames)':<24}" + "".join(f"{PAPER_PHASE_S[p]:>16.2f}" for p in PHASES))


if __name__ == "__main__":
    main()
