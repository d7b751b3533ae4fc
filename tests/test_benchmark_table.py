"""The calibration table's text and its default seed."""

import inspect

import numpy as np
import pytest

from dvrk_gym.calibration import pipeline
from dvrk_gym.calibration.benchmark import BENCHMARK_SEED, YAW_SETTINGS, CircleErrors, calibration_table, format_table


def _table(*methods: str, width_px: int = 1920) -> dict:
    errors = CircleErrors(pixel=np.full(35, 20.0), mm=np.full(35, 1.8), yaw=np.zeros(35), width_px=width_px)
    return {method: {label: errors for label, _ in YAW_SETTINGS} for method in methods}


def test_any_method_name_lines_up_and_a_method_without_a_paper_figure_shows_a_dash():
    text = format_table(_table("DNN", "my gradient boosting"))
    assert "nan" not in text
    summary = text.splitlines()[-3:]
    assert len({len(line) for line in summary}) == 1, summary  # one width for header and rows
    assert summary[2].split()[-2:] == ["-", "-"]
    assert summary[1].split()[-2:] == ["2.14", "-16%"]


def test_every_column_of_the_error_tables_lines_up_under_its_setting_even_with_three_digit_errors():
    """Cells of 29 to 36 characters were padded to 26, so no row lined up with the settings above it."""
    small = CircleErrors(pixel=np.full(35, 4.0), mm=np.full(35, 0.2), yaw=np.zeros(35), width_px=640)
    large = CircleErrors(pixel=np.linspace(50, 900, 35), mm=np.linspace(5, 99, 35), yaw=np.zeros(35), width_px=640)
    text = format_table({"RBT": {label: small for label, _ in YAW_SETTINGS}, "DNN": {label: large for label, _ in YAW_SETTINGS}})
    for section in text.split("\n\n")[:2]:  # pixels, millimetres
        rows = [line for line in section.splitlines() if line.startswith(("method", "RBT", "DNN", "  paper"))]
        assert len(rows) == 5 if "pixels" in section else len(rows) == 3
        assert len({len(line) for line in rows}) == 1, rows  # every row ends where the header does
        header = rows[0]
        ends = [header.index(label) + len(label) for label, _ in YAW_SETTINGS]
        for row in rows[1:]:
            assert all(row[end - 1] != " " and (end == len(row) or row[end] == " ") for end in ends), row  # a cell ends under each label


def test_the_papers_pixels_are_scaled_to_the_width_the_touches_were_judged_in():
    from dvrk_gym import paper

    def paper_row(text: str) -> list[float]:
        return [float(v) for v in next(line for line in text.splitlines() if line.startswith("  paper")).split()[1:]]

    full, third = format_table(_table("DNN")), format_table(_table("DNN", width_px=640))
    np.testing.assert_allclose(paper_row(full), paper.CALIBRATION_PIXELS["DNN"], atol=0.05)  # 1920 x 1080: as printed
    np.testing.assert_allclose(paper_row(third), np.array(paper.CALIBRATION_PIXELS["DNN"]) / 3, atol=0.05)
    assert "scaled to it" in third and "scaled to it" not in full
    mixed = format_table({**_table("DNN"), **_table("RBT", width_px=640)})
    assert not any(line.startswith("  paper") for line in mixed.splitlines()) and "not shown" in mixed
    assert "widths" not in format_table({})  # no rows, nothing to note
    with pytest.raises(ValueError, match="width_px"):
        CircleErrors(pixel=np.zeros(35), mm=np.zeros(35), yaw=np.zeros(35), width_px=0)


def test_the_table_and_the_pipeline_share_one_default_seed():
    assert inspect.signature(calibration_table).parameters["seed"].default == BENCHMARK_SEED
    assert pipeline.PipelineConfig().seed + pipeline.BENCHMARK_SEED_OFFSET == BENCHMARK_SEED


def test_a_pass_tours_the_authors_order_and_its_errors_come_back_per_circle_in_row_major_order():
    import gymnasium as gym

    from dvrk_gym.calibration.benchmark import touch_grid, touch_grid_episodes
    from dvrk_gym.envs.grid_touch import TOUR

    env = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=(320, 180))
    try:
        centres = env.unwrapped.circle_centers
        # a policy that aims a little off each circle, by an amount that differs from circle to circle
        policy = lambda obs: np.array([*centres[env.unwrapped._circle, :2] + [0.001 * (env.unwrapped._circle % 4), 0.0], -0.16, 0.0])  # noqa: E731
        episodes = touch_grid_episodes(env, policy, 0.0, seed=3)
        errors = touch_grid(env, policy, 0.0, seed=3)
    finally:
        env.close()
    assert [e.final_info["circle_index"] for e in episodes] == list(TOUR)
    by_circle = {e.final_info["circle_index"]: e.metrics["mm_error"] for e in episodes}
    np.testing.assert_array_equal(errors.mm, [by_circle[c] for c in range(35)])  # the same pass, put back in circle order
    assert len(set(np.round(errors.mm, 6))) > 4
    assert errors.width_px == 320  # the pixel errors' image, for the table's paper rows


def test_a_pass_refuses_an_order_that_is_not_each_circle_once():
    from dvrk_gym.calibration.benchmark import touch_grid_episodes

    for order in ([0] * 35, list(range(34)), list(range(1, 36))):
        with pytest.raises(ValueError, match="each circle index 0-34 once"):
            touch_grid_episodes(None, None, 0.0, order=order)  # refused before any env is touched


def test_a_calibration_folder_whose_phase_ii_went_row_major_is_refused_not_mixed(small_calibration, tmp_path):
    import dataclasses
    import shutil

    from dvrk_gym.calibration.phase2 import Phase2Data
    from dvrk_gym.calibration.pipeline import PipelineConfig, read_pipeline_settings, run_calibration

    stale = tmp_path / "stale"
    shutil.copytree(small_calibration, stale)
    phase2 = Phase2Data.load(stale / "phase2.npz")
    dataclasses.replace(phase2, circle=np.tile(np.arange(35), len(phase2.circle) // 35)).save(stale / "phase2.npz")
    forests = (stale / "two_phase.zip").read_bytes()
    config = PipelineConfig.from_settings(read_pipeline_settings(stale))
    with pytest.raises(ValueError, match="another order than the authors' tour.*delete it and two_phase.zip"):
        run_calibration(stale, config, progress=False)
    assert (stale / "two_phase.zip").read_bytes() == forests  # nothing made or moved in the folder


def test_the_error_maps_and_the_sweep_figure_say_which_budget_made_them(tmp_path, monkeypatch):
    """A 3-trajectory, 20-epoch run's figures looked like the paper's budget's."""
    from dvrk_gym.calibration import benchmark
    from dvrk_gym.sweep import table as sweep_table

    titles = []
    monkeypatch.setattr(benchmark, "atomic_savefig", lambda figure, path, dpi: titles.append(figure._suptitle.get_text()))
    monkeypatch.setattr(sweep_table, "atomic_savefig", lambda figure, path, dpi: titles.append(figure.axes[0].get_title()))
    config = pipeline.PipelineConfig(n_trajectories=3, dnn_epochs=20, camera_resolution=(640, 360))
    assert config.budget() == "bias paper; 3 trajectories of 93, 20 epochs; 640 x 360 px"
    benchmark.plot_error_maps(_table("DNN"), tmp_path / "maps.png", subtitle=config.budget())
    rows = [{"bias_seed": 0, "calibrator": "dnn", "mean_mm": 2.0}]
    sweep_table.plot_errors(rows, tmp_path / "sweep.png", subtitle=config.budget())
    assert all(title.endswith("\nbias paper; 3 trajectories of 93, 20 epochs; 640 x 360 px") for title in titles) and len(titles) == 2
