"""The paper's two-phase calibration end to end, in stages that are cached on disk.

Phase I collection -> rigid body and DNN fits -> Phase II corrections -> residual forests
-> the calibration table. Each stage writes its result into the output folder and a
re-run loads it instead of recomputing, so an interrupted run resumes. A run refuses to
resume from a folder made with different settings, or by another dvrk_gym (the stamp
records its source fingerprint: :mod:`dvrk_gym.utils.source_fingerprint`).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from dvrk_gym import paper
from dvrk_gym.calibration.benchmark import (
    BENCHMARK_SEED,
    calibration_table,
    format_table,
    paper_table_rules,
    plot_error_maps,
    save_table,
    table_summary,
)
from dvrk_gym.calibration.models.dnn import MAX_EPOCHS, DNNCalibrator
from dvrk_gym.calibration.models.rigid import MIN_GROUP_ROWS, RigidBodyCalibrator
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator
from dvrk_gym.calibration.phase1 import MAX_STEPS_PER_TRAJECTORY, MAX_TRAJECTORIES, Phase1Data, run_paper_phase1
from dvrk_gym.calibration.phase2 import Phase2Data, collect_phase2
from dvrk_gym.evaluation.table_protocol import PROTOCOL_LINES, PROTOCOLS
from dvrk_gym.sim.robot.bias import BIAS_PRESETS
from dvrk_gym.utils.atomic import atomic_write_text, file_sha256
from dvrk_gym.utils.checks import check_choice, check_endoscope_resolution, check_int_fields
from dvrk_gym.utils.run_folder import RunFolder, read_settings

logger = logging.getLogger(__name__)

SETTINGS_STAMP = "pipeline_config.json"
"""The file of a calibration run folder that holds its settings (:class:`PipelineConfig`)."""
CALIBRATOR_FILES = {"rbt": "rbt.zip", "dnn": "dnn.zip", "dnn+rf": "two_phase.zip"}
"""The model file of each calibrator in a calibration run folder, by the calibrator's name."""
STAGES = ("phase1", "rbt", "dnn", "phase2", "forests")
"""The cached stages of a calibration run, in order: the keys of ``timings_s`` for those made (not loaded)."""
MADE_FROM = "made_from.json"
"""The file of a calibration run folder recording the inputs each result was made from:
``{result file: {input file: SHA-256}}``. A result whose input has changed since (a file of
another run put in) is refused, not loaded beside it."""
MAX_INPUT_BYTES = 2**30
"""The largest stage input hashed, bytes (a Phase I of the paper's budget is under 1 MB)."""
RETIRED_CALIBRATOR_FILES = {"rbt": "rbt.npz", "dnn": "dnn.npz", "dnn+rf": "two_phase.npz"}
"""The same in the retired ``.npz`` format, which is no longer read (``calibrate`` makes the new files beside them)."""
BENCHMARK_SEED_OFFSET = BENCHMARK_SEED
"""The benchmark's seed is the run's seed plus this (so run seed 0 gives calibration_table's default)."""


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of a calibration run (the paper's budgets by default), checked when made, so
    that a bad value is refused before a run folder is stamped with it.

    Attributes:
        n_trajectories: Phase I trajectories (the paper: 57).
        steps_per_trajectory: commanded poses per trajectory (the paper: about 92).
        dnn_epochs: DNN training epochs (the paper: 1000).
        bias: the cable bias preset.
        bias_seed: which instrument.
        camera_resolution: endoscope image size, pixels.
        seed: seeds collection, training and evaluation.
    """

    n_trajectories: int = paper.PHASE1_TRAJECTORIES
    steps_per_trajectory: int = paper.PHASE1_POSES_PER_TRAJECTORY
    dnn_epochs: int = paper.DNN_EPOCHS
    bias: str = "paper"
    bias_seed: int = 0
    camera_resolution: tuple[int, int] = paper.ENDOSCOPE_RESOLUTION_PX
    seed: int = 0

    def __post_init__(self) -> None:
        bounds = {
            "n_trajectories": (1, MAX_TRAJECTORIES),
            "steps_per_trajectory": (1, MAX_STEPS_PER_TRAJECTORY),
            "dnn_epochs": (1, MAX_EPOCHS),
            "bias_seed": (0, 2**31 - 1),
            "seed": (0, 2**31 - 1),
        }
        check_int_fields("PipelineConfig", self, bounds)
        check_choice("PipelineConfig.bias", self.bias, sorted(BIAS_PRESETS))
        object.__setattr__(
            self, "camera_resolution", check_endoscope_resolution("PipelineConfig.camera_resolution", self.camera_resolution)
        )

    def budget(self) -> str:
        """The bias preset and the budgets in a line, for figures (a quick run's look like the paper's)."""
        width, height = self.camera_resolution
        trajectories = f"{self.n_trajectories} trajectories of {self.steps_per_trajectory}"
        return f"bias {self.bias}; {trajectories}, {self.dnn_epochs} epochs; {width} x {height} px"

    def env_kwargs(self) -> dict[str, Any]:
        return {"bias": self.bias, "bias_seed": self.bias_seed, "camera_resolution": tuple(self.camera_resolution)}

    @classmethod
    def from_settings(cls, settings: dict[str, Any], source: str = "the settings") -> PipelineConfig:
        """The config of a run folder's stamp (JSON: the resolution comes back as a list).

        Args:
            settings: the stamp's settings.
            source: where they came from, for errors (e.g. "the settings of runs/cal").

        Raises:
            ValueError: they are not a config's fields and values (the message names ``source``).
        """
        try:
            values: dict[str, Any] = {key: (tuple(value) if key == "camera_resolution" else value) for key, value in settings.items()}
            return cls(**values)
        except (TypeError, ValueError, AttributeError) as error:
            raise ValueError(f"{source} are not a calibration's settings ({error})") from None


def read_pipeline_settings(folder: str | os.PathLike) -> dict[str, Any] | None:
    """The settings a calibration run folder was made with, or None if it has none."""
    return read_settings(folder, SETTINGS_STAMP)


def _save(value: Any, path: Path) -> None:
    value.save(path)


FEW_PHASE1_ROWS = 100
"""Fewer kept Phase I rows than this get a warning: the DNN's 183,303 weights (3 x 300) are
fitted to a few points (the authors kept 1939; three trajectories at 640 x 360 keep about 107)."""


def check_phase1_rows(n_kept: int, n_raw: int) -> None:
    """Refuse a Phase I whose kept rows cannot fit the calibrators, and warn of one with few.

    Raises:
        ValueError: fewer than :data:`~dvrk_gym.calibration.models.rigid.MIN_GROUP_ROWS` kept
            rows, with what to change (a small image loses the marker: 7 of 279 rows at 320 x 180).
    """
    advice = "collect more trajectories, or at a higher camera resolution (below 640 x 360 the marker is mostly lost)"
    if n_kept < MIN_GROUP_ROWS:
        raise ValueError(f"Phase I kept {n_kept} of its {n_raw} samples; the calibrators need at least {MIN_GROUP_ROWS}: {advice}")
    if n_kept < FEW_PHASE1_ROWS:
        logger.warning(
            "Phase I kept only %d of its %d samples (the authors kept %d): its models fit few points; %s",
            n_kept,
            n_raw,
            paper.PHASE1_KEPT_SAMPLES,
            advice,
        )


def _run_phase1(config: PipelineConfig, progress: bool) -> Phase1Data:
    return run_paper_phase1(
        n_trajectories=config.n_trajectories,
        seed=config.seed,
        steps_per_trajectory=config.steps_per_trajectory,
        **config.env_kwargs(),
        progress=progress,
    )


def run_calibration(
    out: Path, config: PipelineConfig = PipelineConfig(), *, progress: bool = True, benchmark: bool = True, protocol: str = "paper"
) -> dict[str, Any]:
    """Run (or resume) the whole two-phase calibration and, if asked, its benchmark in ``out``.

    The benchmark sends the predictions by ``protocol``: "paper", the authors' height rules
    for each method (the rigid body's lifted, :mod:`dvrk_gym.evaluation.table_protocol`), or
    "raw", as they are. It is not a setting of the run: one folder can be evaluated both ways.

    Returns:
        ``{"phase1": Phase1Data, "phase2": Phase2Data, "models": {...}, "table": ...,
        "summary": ..., "timings_s": {...}}`` (no table or summary without ``benchmark``).
    """
    check_choice("protocol", protocol, PROTOCOLS)
    out = Path(out)
    if not isinstance(config, PipelineConfig):
        raise ValueError(f"config must be a PipelineConfig (PipelineConfig.from_settings reads a dict), got {type(config).__name__}")
    with RunFolder(out, dataclasses.asdict(config), stamp=SETTINGS_STAMP) as folder:
        return _run_stages(out, folder, config, progress, protocol if benchmark else None)


def _cached_from(folder: RunFolder, inputs: list[str], name: str, **cached: Any) -> Any:
    """``folder.cached(name, **cached)`` for a result made from the files ``inputs`` of the
    folder, recording their digests in :data:`MADE_FROM` (a result there from before the
    record is taken as it is, and recorded).

    Raises:
        ValueError: the result is there, but an input is not the file it was made from.
    """
    records = folder.read_json(MADE_FROM)
    records = records if isinstance(records, dict) else {}
    digests = {input_name: file_sha256(folder.file(input_name), MAX_INPUT_BYTES, "a calibration stage's input") for input_name in inputs}
    recorded = records.get(name)
    if folder.file(name).exists() and isinstance(recorded, dict) and recorded != digests:
        changed = ", ".join(input_name for input_name in inputs if recorded.get(input_name) != digests[input_name])
        raise ValueError(
            f"{folder.file(name)} was made from another {changed} than the one in {folder.path} now (another run's file "
            f"put in?); restore it, or delete {name} and the results made after it to make them again from it"
        )
    value = folder.cached(name, **cached)
    if recorded != digests:
        folder.write_json(MADE_FROM, {**records, name: digests})
    return value


def _run_stages(out: Path, folder: RunFolder, config: PipelineConfig, progress: bool, protocol: str | None) -> dict[str, Any]:
    """The stages; ``protocol`` is the benchmark's, or None for no benchmark."""
    grid = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
    try:
        phase1 = folder.cached("phase1.npz", make=lambda: _run_phase1(config, progress), load=Phase1Data.load, save=_save)
        clean = phase1.cleaned()
        logger.info("Phase I: %d raw samples, %d kept (%.0f%%)", phase1.n_raw, phase1.n_kept, 100 * phase1.n_kept / max(phase1.n_raw, 1))
        check_phase1_rows(phase1.n_kept, phase1.n_raw)
        rbt = _cached_from(
            folder,
            ["phase1.npz"],
            CALIBRATOR_FILES["rbt"],
            make=lambda: RigidBodyCalibrator().fit(clean.X, clean.y),
            load=RigidBodyCalibrator.load,
            save=_save,
        )
        dnn = _cached_from(
            folder,
            ["phase1.npz"],
            CALIBRATOR_FILES["dnn"],
            make=lambda: DNNCalibrator(epochs=config.dnn_epochs, seed=config.seed, progress=progress).fit(clean.X, clean.y),
            load=DNNCalibrator.load,
            save=_save,
        )
        phase2 = _cached_from(
            folder,
            [CALIBRATOR_FILES["dnn"]],
            "phase2.npz",
            make=lambda: collect_phase2(grid, dnn, seed=config.seed, progress=progress),
            load=Phase2Data.load,
            save=_save,
        )
        if not phase2.in_authors_tour:  # cached before the tour: its forests learned another order's hysteresis
            raise ValueError(
                f"{folder.file('phase2.npz')} touched the circles in another order than the authors' tour (a run made before "
                f"dvrk-gym took it); delete it and {CALIBRATOR_FILES['dnn+rf']} to make them again, or use another --out"
            )
        two_phase = _cached_from(
            folder,
            [CALIBRATOR_FILES["dnn"], "phase2.npz"],
            CALIBRATOR_FILES["dnn+rf"],
            make=lambda: TwoPhaseCalibrator(dnn=dnn, seed=config.seed).fit_phase2(phase2.X, phase2.corrected),
            load=TwoPhaseCalibrator.load,
            save=_save,
            stage="forests",
        )
        models = {"RBT": rbt, "DNN": dnn, "DNN+RF": two_phase}
        timings = folder.made_s
        if protocol is None:
            return {"phase1": phase1, "phase2": phase2, "models": models, "timings_s": timings}
        start = time.perf_counter()
        rules = paper_table_rules(list(models), phase2.corrected[:, 2]) if protocol == "paper" else None
        table = calibration_table(grid, models, seed=config.seed + BENCHMARK_SEED_OFFSET, progress=progress, rules=rules)
        timings["benchmark"] = time.perf_counter() - start
    finally:
        grid.close()
    save_table(table, out / "calibration_table.json", protocol=protocol)
    plot_error_maps(
        table,
        out / "calibration_error_maps.png",
        subtitle=f"instrument {config.bias_seed}, seed {config.seed}, {config.budget()}; protocol {protocol}",
    )
    atomic_write_text(out / "calibration_table.txt", f"{PROTOCOL_LINES[protocol]}\n{format_table(table)}\n")
    return {
        "protocol": protocol,
        "phase1": phase1,
        "phase2": phase2,
        "models": models,
        "table": table,
        "summary": table_summary(table),
        "timings_s": timings,
    }
