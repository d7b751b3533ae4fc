"""dvrk-gym reproduce: a tiny run end to end, resuming, determinism across workers, and
the task scheduler."""

import json
import math
import shutil
from pathlib import Path

import pytest
from reproduction_files import files_that_differ

from dvrk_gym import paper
from dvrk_gym.cli.main import main
from dvrk_gym.parallel.task_graph import Task, TaskError, run_tasks
from dvrk_gym.reproduce import TINY, Profile, ReproduceConfig, build_tasks, run_reproduce
from dvrk_gym.reproduce.run import SETTINGS_STAMP, seeded_results
from dvrk_gym.utils.run_folder import SOURCE_KEY, RunFolder, read_settings
from dvrk_gym.utils.source_fingerprint import source_fingerprint


def _numbers(value):
    """Every number in a JSON tree (booleans are not numbers here)."""
    if isinstance(value, dict):
        for item in value.values():
            yield from _numbers(item)
    elif isinstance(value, list):
        for item in value:
            yield from _numbers(item)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield value


def test_tiny_reproduce_writes_report_results_and_figures(tiny_reproduction):
    out = tiny_reproduction.report.parent
    data = json.loads(tiny_reproduction.results.read_text())
    assert set(data["calibration"]) == {"RBT", "DNN", "DNN+RF"}
    for row in data["calibration"].values():
        assert math.isfinite(row["mean_mm"]) and row["mean_mm"] > 0
        assert all(math.isfinite(v) for v in row["per_setting_px"].values())
    cells = {(c["method"], c["fragment"]) for c in data["debridement"]}
    assert cells == {(m, f) for m in ("DNN", "DNN+RF", "sac (RL)") for f in ("pumpkin_seed", "raisin")}
    for cell in data["debridement"]:
        assert cell["picks"] == 2 and cell["success"] + cell["A"] + cell["B"] + cell["C"] <= cell["picks"]
        assert math.isfinite(cell["time_per_fragment_s"]) and cell["time_per_fragment_s"] > 0
    (agent,) = data["rl"]
    assert agent["env_steps"] == 60 and math.isfinite(agent["mean_mm"])
    assert len(data["search"]) == 5 and all(math.isfinite(r["mean_mm2"]) for r in data["search"])
    assert data["phase1"]["raw"] == 60
    # finite numbers only: json writes NaN and inf as bare NaN/Infinity
    numbers = list(_numbers(data))
    assert len(numbers) > 200 and all(math.isfinite(n) for n in numbers)
    for path in data["figures"].values():
        assert (out / path).stat().st_size > 1000, path
    report = tiny_reproduction.report.read_text()
    for heading in ("## Calibration error", "## Debridement", "## Model search", "## Reinforcement-learning baseline", "## Phase I data"):
        assert heading in report
    assert "| DNN+RF, paper | 10.5 | 14.2 | 12.8 | 12.1 | 8.9 | 14.7 | 1.08 |" in report  # the paper beside the simulation
    assert "figures/bias_field.png" in report
    short = sorted({r["epochs"] for r in data["search"] if r["epochs"] is not None})
    assert f"The nets here trained {', '.join(map(str, short))} epochs, not the paper's 1000" in report  # a tiny profile's nets


def test_the_model_search_says_nothing_of_short_training_when_the_nets_had_the_papers():
    from dvrk_gym.reproduce.report import _search_section

    row = {"name": "DNN_u300_h3_relu", "mean_mm2": 1.0, "std_mm2": 0.1, "fold_mm2": [1.0], "split_folds": 10, "epochs": 1000}
    data = {"search": [row, {**row, "name": "Lin_EA", "epochs": None}], "search_paper_mm2": {}, "figures": {}}
    assert not any("epochs, not the paper's" in line for line in _search_section(data))
    data["search"][0]["epochs"] = 30
    assert sum("The nets here trained 30 epochs, not the paper's 1000" in line for line in _search_section(data)) == 1


def test_rerun_resumes_from_the_cache_and_refuses_other_settings(tiny_reproduction, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)  # the shared run stays as it was made
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    assert set(again.data["task_cached"]) == {task.name for task in build_tasks(ReproduceConfig(out=out, profile=TINY))}
    assert again.data["calibration"] == tiny_reproduction.data["calibration"]
    with pytest.raises(ValueError, match="other settings"):
        run_reproduce(ReproduceConfig(out=out, profile=TINY, seed=1, progress=False))


def test_two_workers_give_the_same_numbers(tiny_reproduction, tmp_path):
    two = run_reproduce(ReproduceConfig(out=tmp_path, profile=TINY, workers=2, progress=False))
    assert seeded_results(two.data) == seeded_results(tiny_reproduction.data)  # every number the seed decides
    assert files_that_differ(tiny_reproduction.report.parent, tmp_path) == []  # and the models, data and tables, byte for byte
    assert two.data["calibration"] == tiny_reproduction.data["calibration"]
    assert two.data["debridement"] == [
        {**cell, "wall_s_per_trial": two_cell["wall_s_per_trial"], "wall_s": two_cell["wall_s"]}
        for cell, two_cell in zip(tiny_reproduction.data["debridement"], two.data["debridement"])
    ]
    assert two.data["rl"][0]["mean_mm"] == tiny_reproduction.data["rl"][0]["mean_mm"]
    assert [r["mean_mm2"] for r in two.data["search"]] == [r["mean_mm2"] for r in tiny_reproduction.data["search"]]


def test_bad_settings_are_refused(tmp_path):
    with pytest.raises(ValueError, match="workers"):
        ReproduceConfig(out=tmp_path, workers=0)
    with pytest.raises(ValueError, match="bias"):
        ReproduceConfig(out=tmp_path, bias="rusty")
    with pytest.raises(ValueError, match="search"):
        Profile(name="x", search="exhaustive")
    with pytest.raises(ValueError, match="rl_agents must be GridTouch-v0 agents"):
        Profile(name="x", rl_agents=("sac_pick",))  # picks are judged by debridement, not the grid
    with pytest.raises(ValueError, match="debridement_trials"):
        Profile(name="x", debridement_trials=0)
    assert main(["reproduce", "--quick", "--out", str(tmp_path), "--workers", "0"]) == 2


# ---------------------------------------------------------------- the scheduler
def record(name: str, log: str) -> dict:
    with open(log, "a") as handle:
        handle.write(name + "\n")
    return {"name": name}


def fail(message: str) -> dict:
    raise RuntimeError(message)


def test_tasks_run_after_what_they_need_and_results_are_cached(tmp_path):
    log = tmp_path / "log.txt"
    graph = [
        Task("c", record, {"name": "c", "log": str(log)}, needs=("a", "b"), cost_s=100),
        Task("a", record, {"name": "a", "log": str(log)}, cost_s=1),
        Task("b", record, {"name": "b", "log": str(log)}, needs=("a",), cost_s=5),
    ]
    results = run_tasks(graph, cache_dir=tmp_path / "cache", workers=1, progress=False)
    assert log.read_text().split() == ["a", "b", "c"]
    assert list(results) == ["c", "a", "b"] and results["c"]["name"] == "c" and not results["c"]["cached"]
    again = run_tasks(graph, cache_dir=tmp_path / "cache", workers=1, progress=False)
    assert log.read_text().split() == ["a", "b", "c"]  # nothing ran twice
    assert all(r["cached"] for r in again.values())


def test_bad_graphs_and_failures_are_reported(tmp_path):
    log = str(tmp_path / "log.txt")
    with pytest.raises(ValueError, match="unknown"):
        run_tasks([Task("a", record, {"name": "a", "log": log}, needs=("z",))], cache_dir=tmp_path, progress=False)
    with pytest.raises(ValueError, match="cycle"):
        run_tasks([Task("a", record, needs=("b",)), Task("b", record, needs=("a",))], cache_dir=tmp_path, progress=False)
    with pytest.raises(ValueError, match="unique"):
        run_tasks([Task("a", record), Task("a", record)], cache_dir=tmp_path, progress=False)
    graph = [Task("ok", record, {"name": "ok", "log": log}), Task("bad", fail, {"message": "boom"})]
    for workers in (1, 2):
        with pytest.raises(TaskError, match="'bad' failed: RuntimeError: boom"):
            run_tasks(graph, cache_dir=tmp_path / f"cache{workers}", workers=workers, progress=False)
        assert (tmp_path / f"cache{workers}" / "ok.json").exists()  # finished work stays cached


def test_the_task_that_unlocks_most_work_starts_first(tmp_path):
    log = tmp_path / "log.txt"
    step = lambda name, cost, needs=(): Task(name, record, {"name": name, "log": str(log)}, needs=needs, cost_s=cost)  # noqa: E731
    graph = [step("big", 50), step("root", 10), step("leaf1", 30, ("root",)), step("leaf2", 30, ("root",))]
    run_tasks(graph, cache_dir=tmp_path / "cache", workers=1, progress=False)
    assert log.read_text().split() == ["root", "big", "leaf1", "leaf2"]  # root carries 70 s of work, big 50


# ---------------------------------------------------------------- the run folder
def test_a_run_folder_makes_each_result_once_and_refuses_other_settings(tmp_path):
    made = []

    def make():
        made.append(1)
        return {"x": 1.5}

    def cached(folder):
        return folder.cached(
            "result.json",
            make=make,
            load=lambda path: json.loads(path.read_text()),
            save=lambda value, path: path.write_text(json.dumps(value)),
        )

    settings = {"seed": 0, "profile": {"name": "tiny", "camera_resolution": (480, 270)}}
    first = RunFolder(tmp_path, settings, stamp="config.json")
    assert cached(first) == {"x": 1.5} and set(first.made_s) == {"result"}
    again = RunFolder(tmp_path, {**settings, "profile": {"name": "tiny", "camera_resolution": [480, 270]}}, stamp="config.json")
    assert cached(again) == {"x": 1.5} and again.made_s == {} and len(made) == 1  # loaded, not made again
    assert read_settings(tmp_path, "config.json") == {"seed": 0, "profile": {"name": "tiny", "camera_resolution": [480, 270]}}
    assert json.loads((tmp_path / "config.json").read_text())[SOURCE_KEY] == source_fingerprint().to_json()  # which dvrk_gym made it
    with pytest.raises(ValueError, match=r"other settings \(profile.name: 'tiny' there, 'full' here; seed: 0 there, 1 here"):
        RunFolder(tmp_path, {"seed": 1, "profile": {"name": "full", "camera_resolution": (480, 270)}}, stamp="config.json")
    assert RunFolder(tmp_path).has("result.json")  # without settings: no check


def test_reproduce_refuses_a_folder_made_by_an_older_dvrk_gym_before_running_anything(tmp_path):
    config = ReproduceConfig(out=tmp_path, profile=TINY, progress=False)
    with RunFolder(tmp_path, config.settings(), stamp=SETTINGS_STAMP):
        pass
    stamp = tmp_path / SETTINGS_STAMP
    stamp.write_text(json.dumps(read_settings(tmp_path, SETTINGS_STAMP)))  # as stamped before the fingerprint
    (tmp_path / "report.md").write_text("the older run's report")  # a folder holding only its stamp would be taken
    with pytest.raises(ValueError, match=f"made by an older dvrk_gym: its stamp \\({SETTINGS_STAMP}\\) has no source fingerprint"):
        run_reproduce(config)
    assert not (tmp_path / "tasks").exists() and SOURCE_KEY not in json.loads(stamp.read_text())


# ---------------------------------------------------------------- the paper's numbers
def test_the_committed_full_report_is_the_rendering_of_its_results():
    """docs/reproduce: report.md is what the report's renderer makes of results.json, so the two never disagree."""
    from dvrk_gym.reproduce.report import render_report

    docs = Path(__file__).resolve().parents[1] / "docs" / "reproduce"
    results = json.loads((docs / "results.json").read_text())
    assert results["settings"]["profile"]["name"] == "full"
    assert (docs / "report.md").read_text() == render_report(results)


def test_the_papers_numbers_agree_with_each_other():
    for method, pixels in paper.CALIBRATION_PIXELS.items():
        assert len(pixels) == len(paper.CALIBRATION_SETTINGS)
        assert sum(pixels) / len(pixels) == pytest.approx(paper.CALIBRATION_MEAN_PX[method], abs=0.01)  # the table's mean column
        assert paper.CALIBRATION_MEAN_PX[method] / paper.PX_PER_MM == pytest.approx(paper.CALIBRATION_MEAN_MM[method], abs=0.005)
    for (method, fragment), cell in paper.DEBRIDEMENT_RESULTS.items():
        assert method in paper.METHOD_LABELS and fragment in paper.FRAGMENT_LABELS
        assert sum(cell.values()) <= paper.DEBRIDEMENT_PICKS_PER_CELL == 120
    assert paper.PHASE1_POSES_PER_TRAJECTORY == 93 and paper.PHASE2_TOUCHES == 175
    assert sum(paper.DEBRIDEMENT_PHASE_S.values()) == pytest.approx(paper.TRIAL_S / paper.FRAGMENTS_PER_TRIAL, rel=0.02)
    assert paper.REAL_PHASE1_ROWS == paper.PHASE1_KEPT_SAMPLES


def test_a_profile_is_held_to_the_calibrations_own_bounds():
    """A profile the calibration would refuse is refused when it is made, before a run folder is stamped."""
    from dvrk_gym.calibration.pipeline import MAX_STEPS_PER_TRAJECTORY, MAX_TRAJECTORIES
    from dvrk_gym.reproduce.profiles import Profile

    for field, bound in (("n_trajectories", MAX_TRAJECTORIES), ("steps_per_trajectory", MAX_STEPS_PER_TRAJECTORY)):
        with pytest.raises(ValueError, match=f"{field} must be an int in \\[1, {bound}\\]"):
            Profile(name="big", **{field: bound + 1})


def test_a_tampered_cached_result_is_a_clear_error_and_leaves_the_last_outputs(tiny_reproduction, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)
    before = {name: (out / name).read_bytes() for name in ("report.md", "results.json", "calls.json")}
    calibration = out / "tasks" / "calibration.json"
    calibration.write_text(json.dumps({**json.loads(calibration.read_text()), "summary": 5}))
    with pytest.raises(ValueError, match="cached task results in .* do not hold what the report reads"):
        run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    assert {name: (out / name).read_bytes() for name in before} == before  # nothing half-written, no call logged


def test_an_interrupted_call_counts_in_the_wall_time_of_the_run_it_resumes(tiny_reproduction, tmp_path, monkeypatch):
    """Only the call that finished was counted: a run interrupted after 17 minutes and
    resumed for 2 reported a wall time of 2 minutes."""
    from dvrk_gym.reproduce import run as reproduce_run

    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)
    (out / "tasks" / "bias_field.json").unlink()
    real_run_tasks = reproduce_run.run_tasks

    def run_then_interrupt(*args, **kwargs):
        real_run_tasks(*args, **kwargs)  # bias_field runs again, and is cached
        raise KeyboardInterrupt

    monkeypatch.setattr(reproduce_run, "run_tasks", run_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    interrupted = json.loads((out / "calls.json").read_text())[-1]
    assert interrupted["interrupted"] is True and interrupted["tasks_run"] == 1 and interrupted["wall_s"] > 0
    monkeypatch.setattr(reproduce_run, "run_tasks", real_run_tasks)
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    calls = again.data["calls"]
    assert calls[-2] == interrupted and calls[-1]["interrupted"] is False and calls[-1]["tasks_run"] == 0
    assert again.data["wall_s"]["all_calls"] == pytest.approx(sum(call["wall_s"] for call in calls))
    assert f"{interrupted['wall_s'] / 60:.1f} min for 1 tasks on {interrupted['executor']}, interrupted" in again.report.read_text()


@pytest.mark.parametrize("figure", ["/dev/zero", "fifo"])
def test_a_cached_result_naming_a_figure_that_is_no_file_of_the_run_is_refused(tiny_reproduction, tmp_path, figure):
    """Its bytes were read whole into the report's figures: a FIFO blocked the run, /dev/zero ate the memory."""
    import os

    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)
    if figure == "fifo":
        os.mkfifo(out / "maps.png")
        figure = str(out / "maps.png")
    calibration = out / "tasks" / "calibration.json"
    calibration.write_text(json.dumps({**json.loads(calibration.read_text()), "figure": figure}))
    with pytest.raises(ValueError, match="names .* as its figure: not a file of at most"):
        run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))


def test_a_cached_result_whose_files_are_gone_runs_again(tiny_reproduction, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)
    figure = Path(json.loads((out / "tasks" / "bias_field.json").read_text())["figure"])
    moved = out / "figures" / "bias_field.png"
    assert figure == tiny_reproduction.report.parent / "figures" / "bias_field.png"  # absolute: the copy points at the original
    (out / "tasks" / "bias_field.json").write_text(
        json.dumps({**json.loads((out / "tasks" / "bias_field.json").read_text()), "figure": str(tmp_path / "gone.png")})
    )
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    assert "bias_field" not in again.data["task_cached"] and moved.exists()
    assert again.data["bias"]["rigid_by_yaw_mm"] == tiny_reproduction.data["bias"]["rigid_by_yaw_mm"]


def test_a_calibration_folder_gone_is_made_again_with_the_runs_settings(tiny_reproduction, tmp_path):
    """The calibration task named no files: with its folder gone it stayed cached, and a pick cell
    run again made the calibration with the paper's defaults (57 trajectories, 1000 epochs, 1080p)."""
    from dvrk_gym.calibration.pipeline import PipelineConfig, read_pipeline_settings

    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)
    shutil.rmtree(out / "calibration")
    (out / "tasks" / "debridement_dnn_raisin.json").unlink()
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    assert "calibration" not in again.data["task_cached"]
    made = PipelineConfig.from_settings(read_pipeline_settings(out / "calibration"))
    assert (made.n_trajectories, made.dnn_epochs, made.camera_resolution) == (
        TINY.n_trajectories,
        TINY.dnn_epochs,
        tuple(TINY.camera_resolution),
    )
    outcomes = lambda data: [(cell["calibrator"], cell["fragment"], cell["rows"]) for cell in data["debridement"]]  # noqa: E731
    assert outcomes(again.data) == outcomes(tiny_reproduction.data)  # the same calibration made again: the same picks


def test_a_damaged_model_file_says_to_delete_it_and_then_the_rerun_makes_it_again(tiny_reproduction, tmp_path):
    """A truncated dnn.zip failed its pick cells at every resume with 'the same command resumes'."""
    out = tmp_path / "run"
    shutil.copytree(tiny_reproduction.report.parent, out)
    model = out / "calibration" / "dnn.zip"
    model.write_bytes(model.read_bytes()[:100])
    (out / "tasks" / "debridement_dnn_raisin.json").unlink()
    with pytest.raises(TaskError, match="dnn.zip.*delete that file and run the same command again"):
        run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    model.unlink()
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    assert "calibration" not in again.data["task_cached"]


def test_a_copied_run_folder_links_its_own_figures(tiny_reproduction, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(tiny_reproduction.report.parent, out)
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    report = again.report.read_text()
    assert "](../" not in report and all(not Path(cell["figure"]).is_absolute() for cell in again.data["debridement"])
    assert all((out / cell["figure"]).is_file() for cell in again.data["debridement"])


def test_a_moved_run_folder_keeps_its_cache(tiny_reproduction, tmp_path):
    """Its cached results name files where the run was made: found in the folder, nothing runs again."""
    original, out = tiny_reproduction.report.parent, tmp_path / "moved"
    shutil.copytree(original, out)
    for cached in (out / "tasks").glob("*.json"):  # as if made in a folder since moved away
        cached.write_text(cached.read_text().replace(str(original), str(tmp_path / "gone" / "run")))
    again = run_reproduce(ReproduceConfig(out=out, profile=TINY, workers=1, progress=False))
    assert set(again.data["task_cached"]) == {task.name for task in build_tasks(ReproduceConfig(out=out, profile=TINY))}
    assert "](../" not in again.report.read_text()
