"""Bring your own Phase I model: the paper's residual forests added to scikit-learn's gradient boosting.

Collects the paper's Phase I (57 trajectories), fits a gradient-boosting regressor and the
paper's DNN on it, runs Phase II (35 circles x 5 yaws) aimed by each, adds the per-yaw
residual forests to each through ``TwoPhaseCalibrator(dnn=...)``, and prints the paper's
calibration table for all four, on the same seeds (about 6 minutes on 2 busy cores).

    python benchmarks/bench_own_calibrator.py
"""

import argparse

import gymnasium as gym
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.multioutput import MultiOutputRegressor

from dvrk_gym import TwoPhaseCalibrator, calibration_table, make_calibrator
from dvrk_gym.calibration.benchmark import format_table
from dvrk_gym.calibration.phase1 import run_paper_phase1
from dvrk_gym.calibration.phase2 import collect_phase2

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectories", type=int, default=57, help="Phase I trajectories (the paper: %(default)s)")
    args = parser.parse_args()
    phase1 = run_paper_phase1(n_trajectories=args.trajectories, seed=0).cleaned()
    mine = MultiOutputRegressor(HistGradientBoostingRegressor(random_state=0)).fit(phase1.X, phase1.y)
    paper_dnn = make_calibrator("dnn", seed=0, progress=False).fit(phase1.X, phase1.y)
    grid = gym.make("dvrk_gym/GridTouch-v0")
    phase2 = collect_phase2(grid, mine, seed=0)  # 35 circles x 5 yaws, aimed by my model
    mine_rf = TwoPhaseCalibrator(dnn=mine).fit_phase2(phase2.X, phase2.corrected)
    paper_phase2 = collect_phase2(grid, paper_dnn, seed=0)
    paper_rf = TwoPhaseCalibrator(dnn=paper_dnn).fit_phase2(paper_phase2.X, paper_phase2.corrected)
    print(format_table(calibration_table(grid, {"GBR": mine, "GBR+RF": mine_rf, "DNN": paper_dnn, "DNN+RF": paper_rf})))
