"""Calibration: the paper's models (rigid body, DNN, per-yaw residual forests, two-phase),
baselines for the model search, the authors' data, model files without pickle, the policy
that aims the robot through a calibrator, and the two-phase pipeline with its run folders.

The names below are imported lazily (PEP 562), so importing a light submodule such as
``dvrk_gym.calibration.models.features`` does not pull in torch, scikit-learn and matplotlib.
"""

from __future__ import annotations

from dvrk_gym.utils.lazy_exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(  # PEP 562: each name imported from its module when first asked for
    __name__,
    {
        "CALIBRATOR_FILES": "pipeline",
        "PipelineConfig": "pipeline",
        "run_calibration": "pipeline",
        "load_calibrator": "loading",
        "CalibratedPolicy": "policy",
        "load_paper_phase1": "datasets",
        "load_paper_table_runs": "datasets",
        "DNNCalibrator": "models.dnn",
        "encode_euler": "models.features",
        "encode_quaternion": "models.features",
        "nearest_yaw_index": "models.features",
        "ForestCalibrator": "models.forests",
        "ResidualForests": "models.forests",
        "LinearCalibrator": "models.linear",
        "RigidBodyCalibrator": "models.rigid",
        "SearchResult": "search",
        "cross_validate": "search",
        "format_table": "search",
        "paper_models": "search",
        "plot_search": "search",
        "run_search": "search",
        "ModelFileError": "models.serialization",
        "TwoPhaseCalibrator": "models.two_phase",
    },
)
