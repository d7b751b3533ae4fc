"""A rigid body fitted as the authors first fitted theirs: 35 circles touched by hand at one yaw.

Before their Phase I rows existed, the authors mapped camera to robot with one rigid
transform from the camera positions of the grid's circles to the robot's reported positions
with its jaws pushed onto them by hand (``scripts/mapping.py --collection manual`` of
:data:`dvrk_gym.paper.AUTHORS_CODE`; their versions 00-12). The paper's table did not use it:
its rigid body is the per-yaw one fitted to the Phase I rows, as the package's RBT is
(``click_and_crop_v3.py --use_rigid_body`` loads ``auto_params_matrices_v01``; see
``benchmarks/fidelity_table_runs.py`` for those runs). This benchmark fits the hand-placed
transform in simulation, from the Phase II rows of a calibration run at one yaw (the robot
pushed onto each circle by the simulated person), and prints the paper's calibration table
for it, beside the per-yaw RBT fitted to the same run's Phase I rows (touched as ``dvrk-gym
evaluate`` touches it, lifted as the authors' runs were) and a per-yaw RBT on all five yaws of
Phase II (a hand-placed fit at every yaw). The hand-placed fits put the circles where the jaws
were pushed onto them, so they are sent as they are. About a minute after the calibration:

    dvrk-gym calibrate --out runs/cal
    python benchmarks/bench_manual_rbt.py --calibration runs/cal [--yaw 0]
"""

import argparse

import gymnasium as gym
import numpy as np
from fidelity_table_runs import add_calibration_argument, read_calibration

from dvrk_gym.calibration.benchmark import calibration_table, format_table
from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.calibration.pipeline import BENCHMARK_SEED_OFFSET
from dvrk_gym.evaluation.table_protocol import paper_rules
from dvrk_gym.sim.robot.kinematics import PAPER_YAWS_RAD

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_calibration_argument(parser)
    paper_yaws = [round(float(np.rad2deg(yaw))) for yaw in PAPER_YAWS_RAD]
    parser.add_argument(
        "--yaw", type=int, default=0, choices=paper_yaws, help="the yaw of the hand-placed points, degrees (default: %(default)s)"
    )
    args = parser.parse_args()
    config = read_calibration(parser, args.calibration)
    phase2 = Phase2Data.load(args.calibration / "phase2.npz")
    at_yaw = np.isclose(phase2.orientation[:, 0], np.deg2rad(args.yaw))
    # One transform: with no rows at the other yaws, the rigid body uses its all-rows fit there.
    manual = RigidBodyCalibrator().fit(phase2.X[at_yaw], phase2.corrected[at_yaw])
    every_yaw = RigidBodyCalibrator().fit(phase2.X, phase2.corrected)
    phase1_rbt, _ = load_calibrator(args.calibration, "rbt")
    env = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
    methods = {
        "RBT (Phase I, per yaw)": phase1_rbt,
        f"RBT (35 circles by hand, yaw {args.yaw})": manual,
        "RBT (175 circles by hand, per yaw)": every_yaw,
    }
    print(f"{int(at_yaw.sum())} hand-placed circles at yaw {args.yaw}; instrument: {config.env_kwargs()}")
    rules = {"RBT (Phase I, per yaw)": paper_rules("RBT", phase2.corrected[:, 2])}  # dvrk-gym evaluate's protocol for it
    table = calibration_table(env, methods, seed=config.seed + BENCHMARK_SEED_OFFSET, progress=False, rules=rules)
    print(format_table(table))  # dvrk-gym evaluate's seeds
