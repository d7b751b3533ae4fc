"""Load a calibrator by name from a calibration run folder, running the pipeline there first if it has none.

A calibration run folder (``dvrk-gym calibrate`` or ``evaluate``, or
:func:`~dvrk_gym.calibration.pipeline.run_calibration`) holds the three calibrators of the
paper as pickle-free model files (:data:`~dvrk_gym.calibration.pipeline.CALIBRATOR_FILES`)
and the settings it was made with.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

from dvrk_gym.calibration.models.dnn import DNNCalibrator
from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
from dvrk_gym.calibration.models.serialization import ModelFileError, retired_format_message
from dvrk_gym.calibration.models.two_phase import TwoPhaseCalibrator
from dvrk_gym.calibration.pipeline import (
    CALIBRATOR_FILES,
    RETIRED_CALIBRATOR_FILES,
    SETTINGS_STAMP,
    PipelineConfig,
    read_pipeline_settings,
    run_calibration,
)
from dvrk_gym.utils.run_folder import check_made_here

logger = logging.getLogger(__name__)

CALIBRATOR_LOADERS: dict[str, Any] = {"rbt": RigidBodyCalibrator, "dnn": DNNCalibrator, "dnn+rf": TwoPhaseCalibrator}
"""The class that reads each calibrator's model file, by the calibrator's name."""


def load_calibrator(
    folder: str | os.PathLike,
    name: str,
    *,
    bias: str = "paper",
    bias_seed: int = 0,
    camera_resolution: tuple[int, int] | None = None,
    calibrate_if_missing: bool = False,
) -> tuple[Any, dict[str, Any]]:
    """A calibrator from a calibration run folder, and the run's settings.

    With ``calibrate_if_missing``, runs the calibration pipeline in ``folder`` first if the
    model file is missing or damaged (its stages are cached, so an interrupted run resumes,
    and a damaged file is set aside as ``<name>.corrupt`` and made again); without
    it, a missing model is an error (a mistyped folder would start a calibration of an hour
    at the paper's budget). The settings come from the folder's stamp when it has one, else
    from ``bias``/``bias_seed`` and ``camera_resolution`` (None: the paper's).

    Args:
        folder: a folder written by ``dvrk-gym calibrate`` or ``evaluate``.
        name: "rbt", "dnn" or "dnn+rf".
        bias: the cable bias preset, for a folder without settings.
        bias_seed: which instrument, for a folder without settings.
        camera_resolution: (width, height) px, for a folder without settings.
        calibrate_if_missing: run the pipeline when the folder has no such model, or a
            damaged one.

    Raises:
        ValueError: an unknown calibrator name; a folder stamped by another dvrk_gym (its
            calibrators were fitted on that version's simulated instrument, and would be
            judged on this one's); or, when the pipeline has to run, a folder stamped with
            other settings (:class:`~dvrk_gym.utils.run_folder.RunFolder`).
        FileNotFoundError: the folder has no such model, and ``calibrate_if_missing`` is False.
        ModelFileError: the folder holds the calibrator only in the retired ``.npz`` format (the
            message gives the command that makes it again), or its model file is bad (without
            ``calibrate_if_missing``), or holds a network fitted with another seed or epoch
            count than the folder's settings.
    """
    if name not in CALIBRATOR_FILES:
        raise ValueError(f"unknown calibrator {name!r}; expected one of {sorted(CALIBRATOR_FILES)}")
    folder = Path(folder)
    given = {"bias": bias, "bias_seed": bias_seed} | ({} if camera_resolution is None else {"camera_resolution": list(camera_resolution)})
    settings = read_pipeline_settings(folder) or given
    path = folder / CALIBRATOR_FILES[name]
    retired = folder / RETIRED_CALIBRATOR_FILES[name]
    if not path.exists() and retired.exists():
        raise ModelFileError(retired_format_message(retired))
    check_made_here(folder, SETTINGS_STAMP, remedy="calibrate again with this version: dvrk-gym calibrate --out NEW_FOLDER")
    if not path.exists() and not calibrate_if_missing:
        found = "has no " + path.name if folder.is_dir() else "does not exist"
        raise FileNotFoundError(
            f"{folder} {found}: give a calibration run folder ('dvrk-gym calibrate --out {folder}' makes one), "
            "or calibrate_if_missing=True to run the calibration there"
        )
    model = None
    if path.exists():
        try:
            model = CALIBRATOR_LOADERS[name].load(path)
        except ModelFileError as error:  # damaged: the pipeline sets it aside and makes it again, as `calibrate` does
            if not calibrate_if_missing:
                raise
            logger.warning("%s; running the calibration pipeline there, which makes it again", error)
    if model is None:
        if not path.exists():
            logger.warning("%s has no %s: running the calibration pipeline there (cached stages)", folder, path.name)
        run_calibration(folder, PipelineConfig.from_settings(settings, source=f"the settings of {folder}"), benchmark=False)
        settings = read_pipeline_settings(folder) or settings
        model = CALIBRATOR_LOADERS[name].load(path)
    _check_fitted_as_stamped(model, path, settings)
    return model, settings


def _check_fitted_as_stamped(model: Any, path: Path, settings: dict[str, Any]) -> None:
    """Refuse a network whose file records another seed or epoch count than the folder's settings
    (the pipeline fits it with both): a file of another run, copied in."""
    network = model.dnn if isinstance(model, TwoPhaseCalibrator) else model
    if not isinstance(network, DNNCalibrator) or "seed" not in settings or "dnn_epochs" not in settings:
        return
    fitted, stamped = (network.seed, network.epochs), (settings["seed"], settings["dnn_epochs"])
    if fitted != stamped:
        raise ModelFileError(
            f"{path} holds a network fitted with seed {fitted[0]} for {fitted[1]} epochs, but its folder's settings "
            f"say seed {stamped[0]} and {stamped[1]} epochs: a model file of another run; calibrate again in a new --out"
        )
