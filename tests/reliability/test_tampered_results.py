"""Results and settings files read back by the package, damaged or edited: each refused (or
set aside and made again) with an error naming the file, before any of it is used."""

import json
import math

import numpy as np
import pytest

from dvrk_gym.baselines.comparison import calibration_rows
from dvrk_gym.calibration.phase1 import Phase1Data
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.cli.main import main
from dvrk_gym.reproduce.profiles import Profile
from dvrk_gym.sweep.grid import CALIBRATORS, MAX_UNITS, SweepSettings, Unit, parse_int_list
from dvrk_gym.sweep.run import _load_unit, _unit_file
from dvrk_gym.sweep.table import SETTING_KEYS, unit_rows
from dvrk_gym.utils.atomic import read_json
from dvrk_gym.utils.run_folder import RunFolder

N = 6


def _phase1(**replaced) -> dict:
    arrays = {
        "reported_position": np.zeros((N, 3)),
        "orientation": np.zeros((N, 3)),
        "left_px": np.zeros((N, 2)),
        "right_px": np.zeros((N, 2)),
        "areas_px": np.zeros((N, 2)),
        "camera_position": np.zeros((N, 3)),
        "trajectory": np.arange(N),
        "kept": np.arange(N) % 2 == 0,
    }
    return {**arrays, **replaced}


def test_a_whole_phase1_file_loads(tmp_path):
    Phase1Data(**_phase1()).save(tmp_path / "p.npz")
    assert Phase1Data.load(tmp_path / "p.npz").n_kept == 3
    unseen = _phase1(camera_position=np.where(np.arange(N)[:, None] == 3, np.nan, np.zeros((N, 3))))
    np.savez(tmp_path / "p.npz", **unseen)  # a row the cameras missed, not kept: a NaN is what it holds
    assert Phase1Data.load(tmp_path / "p.npz").n_kept == 3


@pytest.mark.parametrize(
    ("replaced", "message"),
    [
        ({"kept": np.ones(N)}, "'kept' is float64"),  # indices of floats: an IndexError far from the file
        ({"kept": np.zeros(N, dtype=int)}, "'kept' is int64"),  # row indices, not a mask: the wrong rows, silently
        ({"kept": np.ones(N - 1, dtype=bool)}, "one row per sample"),
        ({"orientation": np.zeros((N, 2))}, "'orientation' is float64\\[6, 2\\]"),
        ({"trajectory": np.zeros(N)}, "'trajectory' is float64"),
        ({"camera_position": np.zeros(N * 3)}, "'camera_position'"),
        # values the calibrators cannot fit: once read, a NaN in a kept row failed in the fit, naming neither file nor array
        ({"camera_position": np.where(np.arange(N)[:, None] == 2, np.nan, np.zeros((N, 3)))}, "camera_position of a kept row"),
        ({"reported_position": np.full((N, 3), np.inf)}, "reported_position is not finite in 6 rows"),
        ({name: np.zeros((0,) + value.shape[1:], value.dtype) for name, value in _phase1().items()}, "holds no rows"),
    ],
)
def test_a_phase1_file_of_other_shapes_kinds_or_values_is_refused_naming_it(tmp_path, replaced, message):
    path = tmp_path / "phase1.npz"
    np.savez(path, **_phase1(**replaced))
    with pytest.raises(ValueError, match=message) as refused:
        Phase1Data.load(path)
    assert str(path) in str(refused.value)


def test_a_phase2_file_with_a_position_that_is_not_finite_is_refused(tmp_path):
    path = tmp_path / "phase2.npz"
    rows = {name: np.zeros((4, 3)) for name in ("camera_position", "orientation", "commanded", "corrected")}
    rows["corrected"][1, 2] = np.nan
    np.savez(path, **rows, circle=np.arange(4))
    with pytest.raises(ValueError, match="corrected is not finite in 1 rows"):
        Phase2Data.load(path)


def test_a_phase2_file_with_circles_as_floats_is_refused(tmp_path):
    path = tmp_path / "phase2.npz"
    rows = {name: np.zeros((4, 3)) for name in ("camera_position", "orientation", "commanded", "corrected")}
    np.savez(path, **rows, circle=np.zeros(4))
    with pytest.raises(ValueError, match="'circle' is float64"):
        Phase2Data.load(path)


def _unit_result() -> dict:
    settings = {label: {"mean_mm": 1.0, "mean_px": 9.0} for label in SETTING_KEYS}
    errors = {"mean_mm": 1.0, "sem_mm": 0.1, "mean_px": 9.0, "sem_px": 0.5, "settings": settings, "benchmark_s": 3.0}
    return {
        "config": {"bias_seed": 0, "seed": 0},
        "phase1": {"raw": 10, "kept": 4},
        "stages_s": {},
        "calibrators": {name: dict(errors) for name in CALIBRATORS},
        "wall_s": 60.0,
    }


def _edit(edit):
    result = _unit_result()
    edit(result)
    return result


@pytest.mark.parametrize(
    "edit",
    [
        lambda r: r.update(calibrators={"rbt": 5, "dnn": 5, "dnn+rf": 5}),
        lambda r: r["calibrators"]["dnn"].clear(),
        lambda r: r.pop("phase1"),
        lambda r: r["calibrators"]["rbt"].update(mean_mm=float("nan")),
        lambda r: r["calibrators"]["rbt"].update(mean_mm="x"),
        lambda r: r["calibrators"]["rbt"]["settings"]["yaw 0"].update(mean_px=True),
        lambda r: r.update(config={"bias_seed": 1, "seed": 0}),
    ],
)
def test_a_tampered_sweep_unit_is_run_again_not_tabled(tmp_path, edit, caplog):
    with RunFolder(tmp_path) as folder:
        unit = Unit(bias_seed=0, seed=0)
        (tmp_path / "units").mkdir()
        folder.write_json(_unit_file(unit.name), _edit(edit))
        assert _load_unit(folder, unit) is None
        assert "running the unit again" in caplog.text
        folder.write_json(_unit_file(unit.name), _unit_result())
        assert _load_unit(folder, unit) == _unit_result()


def test_unit_rows_name_the_bad_number():
    with pytest.raises(ValueError, match="rbt's mean_mm is nan"):
        unit_rows(0, 0, _edit(lambda r: r["calibrators"]["rbt"].update(mean_mm=math.nan)), CALIBRATORS)


def test_a_huge_sweep_is_refused_before_its_grid_is_built():
    with pytest.raises(ValueError, match=f"at most {MAX_UNITS:,}"):
        parse_int_list("0-100000000000", "--bias-seeds")
    with pytest.raises(ValueError, match="100,000 units"):
        SweepSettings(bias_seeds=tuple(range(1000)), seeds=tuple(range(100)))


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{}", "KeyError"),
        ("[]", "not a calibration table"),
        ('{"summary": 5}', "not a calibration table"),
        ('{"summary": {"RBT": {"all settings": {"mm": {"mean": "x"}, "pixel": {"mean": 1}}}}}', r"RBT's mean error \(mm\) must be"),
        ('{"summary": {"RBT": {"all settings": {"mm": {"mean": NaN}, "pixel": {"mean": 1}}}}}', r"mean error \(mm\) must be .* got nan"),
        ('{"summary": {"RBT": {"all settings": {"mm": {"mean": 1}, "pixel": {"mean": -5}}}}}', r"mean error \(px\) must be .* got -5"),
        ('{"summary": {"RBT": {"all settings": {"mm": {"mean": 1' + "0" * 400 + '}, "pixel": {"mean": 1}}}}}', "too large for a float"),
        ("not json", "is not valid JSON"),
    ],
)
def test_a_damaged_calibration_table_is_refused_naming_it(tmp_path, content, message):
    table = tmp_path / "calibration_table.json"
    table.write_text(content)
    with pytest.raises(ValueError, match=message) as refused:
        calibration_rows(tmp_path)
    assert str(table) in str(refused.value)


def test_json_is_read_only_from_a_regular_file_of_bounded_size(tmp_path):
    with pytest.raises(ValueError, match="/dev/zero is not a regular file"):
        read_json("/dev/zero")
    big = tmp_path / "big.json"
    big.write_text(json.dumps([0] * 1000))
    with pytest.raises(ValueError, match="a JSON file read here has at most 100"):
        read_json(big, max_bytes=100)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match="deep.json is not valid JSON"):
        read_json(deep)
    with pytest.raises(ValueError, match="profile /dev/zero"):
        Profile.from_file("/dev/zero")
    twice = tmp_path / "twice.json"  # the last "name" won, silently
    twice.write_text('{"name": "small", "phase1_trajectories": 2, "nested": {"a": 1, "a": 2}, "name": "paper"}')
    with pytest.raises(ValueError, match="twice.json is not valid JSON .*an object names \\['a'\\] more than once"):
        read_json(twice)
    with pytest.raises(ValueError, match="names \\['a'\\] more than once"):
        Profile.from_file(twice)


def test_fidelity_checks_its_out_before_collecting(tmp_path, capsys, monkeypatch):
    import dvrk_gym.fidelity.comparison as comparison

    monkeypatch.setattr(comparison, "run_fidelity", lambda **_: pytest.fail("collected before checking --out"))
    afile = tmp_path / "afile"
    afile.write_text("")
    assert main(["fidelity", "--trajectories", "1", "--out", str(afile)]) == 2
    assert "afile" in capsys.readouterr().err


def test_a_dunder_in_an_error_is_not_taken_for_a_flag():
    import argparse

    from dvrk_gym.cli.main import _one_line

    text = _one_line(TypeError("TrainConfig.__init__() got an unexpected keyword argument 'x'"), argparse.Namespace(seed=0))
    assert "TrainConfig.__init__()" in text


def test_a_lock_path_that_is_no_regular_file_is_refused_not_waited_on(tmp_path):
    import os

    os.mkfifo(tmp_path / "run.lock")  # reading it would block for ever
    with pytest.raises(ValueError, match="run.lock is not a regular file"):
        RunFolder(tmp_path)


def test_opening_a_run_folder_leaves_the_temporary_files_of_runs_in_its_subfolders(tmp_path):
    inner = tmp_path / "calibration"
    inner.mkdir()
    (inner / "run.lock").write_text("")
    theirs, ours = inner / ".phase1.abc.partial.npz", tmp_path / ".results.abc.partial.json"
    theirs.write_text("being written")
    ours.write_text("left by a kill")
    with RunFolder(tmp_path):
        pass
    assert theirs.exists() and not ours.exists()


@pytest.mark.parametrize("damage", [b"PK\x03\x04 cut short", b""], ids=["cut", "empty"])
def test_reproduces_rl_task_sets_a_damaged_training_state_aside_and_trains_from_the_start(tmp_path, caplog, damage):
    """It failed the task, and every rerun the same way, while saying the same command resumes."""
    import logging

    from dvrk_gym.reproduce import tasks

    settings = {"steps": 20, "seed": 0, "eval_points": 1, "bias": "paper", "bias_seed": 0, "resolution": (320, 180), "benchmark_seed": 1000}
    damaged, clean = tmp_path / "damaged", tmp_path / "clean"
    damaged.mkdir()
    (damaged / "training_state.zip").write_bytes(damage)
    with caplog.at_level(logging.WARNING, logger="dvrk_gym.reproduce.tasks"):
        result = tasks.rl_agent("sac", out=str(damaged), **settings)
    assert "moved it to" in caplog.text and "training_state.zip.corrupt" in caplog.text
    assert (damaged / "training_state.zip.corrupt").read_bytes() == damage and not (damaged / "training_state.zip").exists()
    fresh = tasks.rl_agent("sac", out=str(clean), **settings)
    assert result["curve"] == fresh["curve"] and result["env_steps"] == fresh["env_steps"] == 20
    assert result["summary"] == fresh["summary"] and result["mean_mm"] == fresh["mean_mm"]
