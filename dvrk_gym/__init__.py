"""dvrk-gym: a simulated da Vinci Research Kit for calibration and debridement research.

Importing the package registers its Gymnasium environments::

    import gymnasium as gym
    import dvrk_gym

    env = gym.make("dvrk_gym/GridTouch-v0", bias="paper", bias_seed=0)

The public API is importable from here (``from dvrk_gym import CalibratedPolicy``); each name
is imported from its module on first use, so ``import dvrk_gym`` stays light (no torch,
scikit-learn or pybullet until a name that needs them is asked for). ``__all__`` lists them;
``ARCHITECTURE.md`` says where each layer lives.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from dvrk_gym.envs import ENV_ENTRY_POINTS, register_envs
from dvrk_gym.utils.lazy_exports import LazyExports

__version__ = "0.1.0"

_EXPORTS = {
    # the environments and their settings
    "CalibrationExplorationEnv": "envs.exploration",
    "ExplorationConfig": "envs.configs",
    "GridTouchEnv": "envs.grid_touch",
    "GridTouchConfig": "envs.configs",
    "DebridementEnv": "envs.debridement",
    "DebridementConfig": "envs.debridement_config",
    "PickTiming": "envs.debridement_config",
    "fragment_target": "envs.debridement",
    "BiasConfig": "sim.robot.bias",
    "DvrkWorld": "sim.world",
    "WorldConfig": "sim.world",
    "DebridementTable": "sim.table.table",
    # the paper's calibrators, as models and as a policy
    "CalibratedPolicy": "calibration.policy",
    "Calibrator": "calibration.policy",
    "RigidBodyCalibrator": "calibration.models.rigid",
    "LinearCalibrator": "calibration.models.linear",
    "ForestCalibrator": "calibration.models.forests",
    "DNNCalibrator": "calibration.models.dnn",
    "ResidualForests": "calibration.models.forests",
    "TwoPhaseCalibrator": "calibration.models.two_phase",
    "make_calibrator": "calibration.models.catalog",
    "load_calibrator": "calibration.loading",
    "ModelFileError": "calibration.models.serialization",
    "PipelineConfig": "calibration.pipeline",
    "run_calibration": "calibration.pipeline",
    "calibration_table": "calibration.benchmark",
    "load_paper_phase1": "calibration.datasets",
    "load_paper_table_runs": "calibration.datasets",
    # how close a simulated instrument is to the real robot
    "FidelityStatistics": "fidelity.statistics",
    "fidelity_statistics": "fidelity.statistics",
    "run_fidelity": "fidelity.comparison",
    # evaluating any policy
    "run_episodes": "evaluation.episodes",
    "summarize": "evaluation.episodes",
    "run_trials": "evaluation.trials",
    # the paper end to end
    "ReproduceConfig": "reproduce.run",
    "run_reproduce": "reproduce.run",
    # sweeps over instruments, calibrators and seeds (locally or on Dask)
    "SweepSettings": "sweep.grid",
    "LocalExecutor": "parallel.executors",
    "run_sweep": "sweep.run",
}
_LAZY = LazyExports(__name__, _EXPORTS)
__all__ = ["ENV_IDS", "__version__", "register_envs", *_LAZY.names]
__getattr__ = _LAZY.load  # PEP 562: a public name is imported when first asked for
__dir__ = _LAZY.dir

ENV_IDS: tuple[str, ...] = tuple(ENV_ENTRY_POINTS)
"""The registered environment ids: ``dvrk_gym/CalibrationExploration-v0``, ``GridTouch-v0``, ``Debridement-v0``."""

if TYPE_CHECKING:  # what type checkers and editors see; at run time the names load lazily
    from dvrk_gym.calibration.benchmark import calibration_table
    from dvrk_gym.calibration.datasets import load_paper_phase1, load_paper_table_runs
    from dvrk_gym.calibration.loading import load_calibrator
    from dvrk_gym.calibration.models.catalog import make_calibrator
    from dvrk_gym.calibration.models.dnn import DNNCalibrator
    from dvrk_gym.calibration.models.forests import ForestCalibrator, ResidualForests
    from dvrk_gym.calibration.models.linear import LinearCalibrator
    from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
    from dvrk_gym.calibration.models.serialization import ModelFileError
    from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator
    from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
    from dvrk_gym.calibration.policy import CalibratedPolicy, Calibrator
    from dvrk_gym.envs.configs import ExplorationConfig, GridTouchConfig
    from dvrk_gym.envs.debridement import DebridementEnv, fragment_target
    from dvrk_gym.envs.debridement_config import DebridementConfig, PickTiming
    from dvrk_gym.envs.exploration import CalibrationExplorationEnv
    from dvrk_gym.envs.grid_touch import GridTouchEnv
    from dvrk_gym.evaluation.episodes import run_episodes, summarize
    from dvrk_gym.evaluation.trials import run_trials
    from dvrk_gym.fidelity.comparison import run_fidelity
    from dvrk_gym.fidelity.statistics import FidelityStatistics, fidelity_statistics
    from dvrk_gym.parallel.executors import LocalExecutor
    from dvrk_gym.reproduce.run import ReproduceConfig, run_reproduce
    from dvrk_gym.sim.robot.bias import BiasConfig
    from dvrk_gym.sim.table.table import DebridementTable
    from dvrk_gym.sim.world import DvrkWorld, WorldConfig
    from dvrk_gym.sweep.grid import SweepSettings
    from dvrk_gym.sweep.run import run_sweep

register_envs()
