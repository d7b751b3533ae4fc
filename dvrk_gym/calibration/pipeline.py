"""The paper's two-phase calibration end to end, in stages that are cached on disk.

Phase I collection -> rigid body and DNN fits -> Phase II corrections -> residual forests
-> the calibration table. Each stage writes its result into the output folder and a
re-run loads it instead of recomputing, so an interrupted run resumes. A run refuses to
resume from a folder made with different settings.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym

from dvrk_gym.calibration.benchmark import calibration_table, format_table, plot_error_maps, save_table, table_summary
from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.phase1 import PaperExplorationPolicy, Phase1Data, collect_phase1
from dvrk_gym.calibration.phase2 import Phase2Data, collect_phase2
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of a calibration run (the paper's budgets by default).

    Attributes:
        n_trajectories: Phase I trajectories (the paper: 57).
        steps_per_trajectory: commanded poses per trajectory (the paper: about 92).
        dnn_epochs: DNN training epochs (the paper: 1000).
        bias: the cable bias preset.
        bias_seed: which instrument.
        camera_resolution: endoscope image size, pixels.
        seed: seeds collection, training and evaluation.
    """

    n_trajectories: int = 57
    steps_per_trajectory: int = 93
    dnn_epochs: int = 1000
    bias: str = "paper"
    bias_seed: int = 0
    camera_resolution: tuple[int, int] = (1920, 1080)
    seed: int = 0

    def env_kwargs(self) -> dict[str, Any]:
        return {"bias": self.bias, "bias_seed": self.bias_seed, "camera_resolution": tuple(self.camera_resolution)}


def _cached(path: Path, load: Callable[[Path], Any], make: Callable[[], Any], save: Callable[[Any, Path], None], timings: dict, stage: str) -> Any:
    if path.exists():
        logger.info("%s: loading %s", stage, path)
        return load(path)
    start = time.perf_counter()
    value = make()
    timings[stage] = time.perf_counter() - start
    save(value, path)
    return value


def _check_folder(out: Path, config: PipelineConfig) -> None:
    out.mkdir(parents=True, exist_ok=True)
    stamp = out / "pipeline_config.json"
    wanted = json.dumps(dataclasses.asdict(config), sort_keys=True, default=list)
    if stamp.exists() and json.loads(stamp.read_text()) != json.loads(wanted):
        raise ValueError(f"{out} holds a run with other settings ({stamp.read_text().strip()}); use another --out or delete it")
    stamp.write_text(wanted)


def run_calibration(out: Path, config: PipelineConfig = PipelineConfig(), progress: bool = True, benchmark: bool = True) -> dict[str, Any]:
    """Run (or resume) the whole two-phase calibration and, if asked, its benchmark in ``out``.

    Returns:
        ``{"phase1": Phase1Data, "phase2": Phase2Data, "models": {...}, "table": ...,
        "summary": ..., "timings_s": {...}}`` (no table or summary without ``benchmark``).
    """
    out = Path(out)
    _check_folder(out, config)
    timings: dict[str, float] = {}
    exploration = gym.make("dvrk_gym/CalibrationExploration-v0", max_steps=config.steps_per_trajectory, **config.env_kwargs())
    grid = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
    try:
        phase1 = _cached(
            out / "phase1.npz", Phase1Data.load,
            lambda: collect_phase1(exploration, PaperExplorationPolicy(seed=config.seed), config.n_trajectories, seed=config.seed, progress=progress),
            lambda data, path: data.save(path), timings, "phase1",
        )
        clean = phase1.cleaned()
        logger.info("Phase I: %d raw samples, %d kept (%.0f%%)", phase1.n_raw, phase1.n_kept, 100 * phase1.n_kept / max(phase1.n_raw, 1))
        rbt = _cached(out / "rbt.npz", RigidBodyCalibrator.load, lambda: RigidBodyCalibrator().fit(clean.X, clean.y), lambda m, p: m.save(p), timings, "rbt")
        dnn = _cached(
            out / "dnn.npz", DNNCalibrator.load,
            lambda: DNNCalibrator(epochs=config.dnn_epochs, seed=config.seed, progress=progress).fit(clean.X, clean.y),
            lambda m, p: m.save(p), timings, "dnn",
        )
        phase2 = _cached(
            out / "phase2.npz", Phase2Data.load, lambda: collect_phase2(grid, dnn, seed=config.seed, progress=progress),
            lambda data, path: data.save(path), timings, "phase2",
        )
        two_phase = _cached(
            out / "two_phase.npz", TwoPhaseCalibrator.load,
            lambda: TwoPhaseCalibrator(dnn=dnn, seed=config.seed).fit_phase2(phase2.X, phase2.corrected),
            lambda m, p: m.save(p), timings, "forests",
        )
        models = {"RBT": rbt, "DNN": dnn, "DNN+RF": two_phase}
        if not benchmark:
            return {"phase1": phase1, "phase2": phase2, "models": models, "timings_s": timings}
        start = time.perf_counter()
        table = calibration_table(grid, models, seed=config.seed + 1000, progress=progress)
        timings["benchmark"] = time.perf_counter() - start
    finally:
        exploration.close()
        grid.close()
    save_table(table, out / "calibration_table.json")
    plot_error_maps(table, out / "calibration_error_maps.png")
    (out / "calibration_table.txt").write_text(format_table(table) + "\n")
    return {
        "phase1": phase1,
        "phase2": phase2,
        "models": models,
        "table": table,
        "summary": table_summary(table),
        "timings_s": timings,
    }
