"""The calibration table's text and its default seed."""

import inspect

import numpy as np

from dvrk_gym.calibration import pipeline
from dvrk_gym.calibration.benchmark import BENCHMARK_SEED, YAW_SETTINGS, CircleErrors, calibration_table, format_table


def _table(*methods: str) -> dict:
    errors = CircleErrors(pixel=np.full(35, 20.0), mm=np.full(35, 1.8), yaw=np.zeros(35))
    return {method: {label: errors for label, _ in YAW_SETTINGS} for method in methods}


def test_any_method_name_lines_up_and_a_method_without_a_paper_figure_shows_a_dash():
    text = format_table(_table("DNN", "my gradient boosting"))
    assert "nan" not in text
    summary = text.splitlines()[-3:]
    assert len({len(line) for line in summary}) == 1, summary  # one width for header and rows
    assert summary[2].split()[-2:] == ["-", "-"]
    assert summary[1].split()[-2:] == ["2.14", "-16%"]


def test_the_table_and_the_pipeline_share_one_default_seed():
    assert inspect.signature(calibration_table).parameters["seed"].default == BENCHMARK_SEED
    assert pipeline.PipelineConfig().seed + pipeline.BENCHMARK_SEED_OFFSET == BENCHMARK_SEED
