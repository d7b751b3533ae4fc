"""Calibration: the paper's models (rigid body, DNN, per-yaw residual forests, two-phase),
baselines for the model search, the authors' data, and model files without pickle."""

from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.calibration.dnn import DNNCalibrator
from dvrk_gym.calibration.features import encode_euler, encode_quaternion, nearest_yaw_index
from dvrk_gym.calibration.forests import ForestCalibrator, ResidualForests
from dvrk_gym.calibration.linear import LinearCalibrator
from dvrk_gym.calibration.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.search import (
    SearchResult, cross_validate, format_table, paper_models, plot_search, run_search,
)
from dvrk_gym.calibration.serialization import ModelFileError
from dvrk_gym.calibration.two_phase import TwoPhaseCalibrator

__all__ = [
    "DNNCalibrator", "ForestCalibrator", "LinearCalibrator", "ModelFileError",
    "ResidualForests", "RigidBodyCalibrator", "SearchResult", "TwoPhaseCalibrator",
    "cross_validate", "encode_euler", "encode_quaternion", "format_table", "load_paper_phase1",
    "nearest_yaw_index", "paper_models", "plot_search", "run_search",
]
