"""Sweeps: the grid, the table, resuming and refusing, local processes and Dask giving the same numbers, the CLI."""

import csv
import dataclasses
import gc
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from dvrk_gym.calibration.benchmark import YAW_SETTINGS
from dvrk_gym.calibration.pipeline import PipelineConfig, run_calibration
from dvrk_gym.cli.main import main
from dvrk_gym.sweep import (
    COLUMN_DOCS,
    COLUMNS,
    LocalExecutor,
    Outcome,
    SweepError,
    SweepSettings,
    Unit,
    format_rows,
    parse_calibrators,
    parse_int_list,
    run_sweep,
    run_unit,
)
from dvrk_gym.sweep.run import SETTINGS_STAMP
from dvrk_gym.sweep.table import TIME_COLUMNS
from dvrk_gym.sweep.unit import SCRATCH_PREFIX
from dvrk_gym.utils.parent_watch import host_label
from dvrk_gym.utils.run_folder import SOURCE_KEY
from dvrk_gym.utils.source_fingerprint import source_fingerprint
from dvrk_gym.utils.torch_threads import torch_threads

TINY = PipelineConfig(n_trajectories=3, steps_per_trajectory=30, dnn_epochs=5, camera_resolution=(640, 360))
"""A budget that makes a unit take seconds (its numbers mean nothing, but they are real)."""


# --- the grid ---------------------------------------------------------------------------


def test_ranges_and_calibrator_lists_parse_and_bad_ones_say_what_is_allowed():
    assert parse_int_list("0-4", "--bias-seeds") == (0, 1, 2, 3, 4)
    assert parse_int_list("0,3,7-9", "--bias-seeds") == (0, 3, 7, 8, 9)
    assert parse_int_list(" 5 ", "--seeds") == (5,)
    for text, message in (
        ("4-0", "empty; write it low-high, e.g. '0-4'"),
        ("", "not a non-negative number"),
        ("a-3", "not a non-negative number"),
        ("0-2,1", "repeats"),
        ("-1", "not a non-negative number"),
        ("0--3", "not a non-negative number"),
        ("1-2-3", "not a non-negative number"),
        ("\u0663", "not a non-negative number"),  # ARABIC-INDIC DIGIT THREE: int() reads it as 3
        ("0-\uff14", "not a non-negative number"),  # FULLWIDTH DIGIT FOUR
    ):
        with pytest.raises(ValueError, match=message):
            parse_int_list(text, "--bias-seeds")
    assert parse_int_list("0-4", "--bias-seeds") == parse_int_list(" 0 - 4 ", "--bias-seeds")  # what the empty range's message suggests
    assert parse_calibrators("rbt, DNN,dnn+rf") == ("rbt", "dnn", "dnn+rf")
    for text, message in (("rbt,knn", "unknown.*expected some of rbt,dnn,dnn\\+rf"), (",", "names none"), ("dnn,dnn", "repeats")):
        with pytest.raises(ValueError, match=message):
            parse_calibrators(text)


def test_settings_refuse_an_empty_or_bad_grid_and_a_bad_budget():
    for kwargs, message in (
        ({"bias_seeds": ()}, "bias_seeds is empty"),
        ({"seeds": (0, 0)}, "repeats"),
        ({"bias_seeds": (-1,)}, "non-negative"),
        ({"bias_seeds": (0.5,)}, "non-negative integers"),
        ({"seeds": (True,)}, "non-negative integers"),
        ({"calibrators": ()}, "calibrators is empty"),
        ({"calibrators": ("rbt", "svm")}, "unknown calibrators"),
        ({"calibrators": "rbt"}, "got the string 'rbt'"),  # not the calibrators 'r', 'b' and 't'
        ({"pipeline": {"bias": "paper"}}, "pipeline must be a PipelineConfig"),
        ({"bias_seeds": (2**31,)}, "up to 2147483647"),  # refused here, not after the folder is stamped
    ):
        with pytest.raises(ValueError, match=message):
            SweepSettings(**kwargs)
    for kwargs, message in (
        ({"bias": "wobbly"}, "PipelineConfig.bias must be one of"),
        ({"dnn_epochs": 0}, "PipelineConfig.dnn_epochs must be"),
    ):
        with pytest.raises(ValueError, match=message):  # refused before a sweep can be set up with it
            PipelineConfig(**kwargs)


def test_units_are_instrument_and_seed_and_the_stamp_leaves_the_grid_out():
    settings = SweepSettings(bias_seeds=[3, np.int64(1)], seeds=range(0, 3, 2), pipeline=TINY)
    assert settings.bias_seeds == (3, 1) and type(settings.bias_seeds[1]) is int
    assert [unit.name for unit in settings.units()] == ["bias3-seed0", "bias3-seed2", "bias1-seed0", "bias1-seed2"]
    config = settings.unit_config(Unit(bias_seed=1, seed=2))
    assert (config.bias_seed, config.seed, config.dnn_epochs) == (1, 2, 5)
    stamp = settings.stamp()["pipeline"]
    assert "bias_seed" not in stamp and "seed" not in stamp and stamp["dnn_epochs"] == 5
    assert SweepSettings(bias_seeds=(7,), calibrators=("rbt",), pipeline=TINY).stamp() == settings.stamp()


# --- resuming, refusing, failing (with stand-in units: the real ones are tested below) ----


def stand_in_result(config: PipelineConfig) -> dict:
    """A unit's result shaped as run_unit's, with numbers made from the unit's name."""
    base = 10.0 * config.bias_seed + config.seed

    def errors(offset: float) -> dict:
        settings = {
            label: {"mean_mm": base + offset + k / 8, "mean_px": 3 * (base + offset) + k} for k, (label, _) in enumerate(YAW_SETTINGS)
        }
        return {
            "mean_mm": base + offset,
            "sem_mm": 0.1,
            "mean_px": 3 * (base + offset),
            "sem_px": 0.3,
            "settings": settings,
            "benchmark_s": 1.0,
        }

    calibrators = {"rbt": errors(0.3), "dnn": errors(0.2), "dnn+rf": errors(0.1)}
    return {
        "config": {"bias_seed": config.bias_seed, "seed": config.seed},
        "phase1": {"raw": 90, "kept": 40},
        "calibrators": calibrators,
        "wall_s": 2.0,
    }


class StandInExecutor:
    """Answers each unit with :func:`stand_in_result` in this process, failing the units asked."""

    description = "stand-in units"

    def __init__(self, fail=()):
        self.fail = set(fail)
        self.submitted = []

    def map_unordered(self, function, items):
        assert function is run_unit  # the sweep submits the real unit; only the answer is stood in
        for config in reversed(items):  # any order
            self.submitted.append(Unit(config.bias_seed, config.seed).name)
            if (config.bias_seed, config.seed) in self.fail:
                yield Outcome(config, None, RuntimeError("the worker died"))
            else:
                yield Outcome(config, stand_in_result(config), None)


def read_rows(path):
    with open(path, newline="") as file:
        return list(csv.DictReader(file))


def test_a_resumed_sweep_runs_nothing_and_a_larger_grid_runs_only_the_new_units(tmp_path):
    settings = SweepSettings(bias_seeds=(0, 1), seeds=(0,), pipeline=TINY)
    first = StandInExecutor()
    result = run_sweep(settings, tmp_path, first, progress=False)
    assert sorted(first.submitted) == ["bias0-seed0", "bias1-seed0"] and set(result.computed) == set(first.submitted)
    assert sorted(path.name for path in (tmp_path / "units").iterdir()) == ["bias0-seed0.json", "bias1-seed0.json"]  # no temp files
    again = StandInExecutor()
    resumed = run_sweep(settings, tmp_path, again, progress=False)
    assert again.submitted == [] and resumed.computed == () and resumed.loaded == ("bias0-seed0", "bias1-seed0")
    assert resumed.rows == result.rows
    grown = StandInExecutor()
    larger = run_sweep(SweepSettings(bias_seeds=(0, 1, 2), seeds=(0, 1), pipeline=TINY), tmp_path, grown, progress=False)
    assert sorted(grown.submitted) == ["bias0-seed1", "bias1-seed1", "bias2-seed0", "bias2-seed1"]
    assert len(larger.rows) == 3 * 2 * 3


@pytest.mark.parametrize(
    ("settings", "executor", "message"),
    [
        ({"bias_seeds": (0,)}, StandInExecutor(), "settings must be a SweepSettings"),
        (SweepSettings(bias_seeds=(0,), pipeline=TINY), None, "executor must be an Executor"),
        (SweepSettings(bias_seeds=(0,), pipeline=TINY), "local", "executor must be an Executor"),
    ],
)
def test_a_sweep_of_no_settings_or_no_executor_is_refused_before_its_folder_is_made(tmp_path, settings, executor, message):
    with pytest.raises(TypeError, match=message):
        run_sweep(settings, tmp_path / "sweep", executor, progress=False)
    assert not (tmp_path / "sweep").exists()  # it wrote a stamp, a units folder and a lock, then failed


def test_a_sweep_whose_units_folder_became_a_file_says_so_and_keeps_it(tmp_path):
    run_sweep(SweepSettings(bias_seeds=(0,), pipeline=TINY), tmp_path, StandInExecutor(), progress=False)
    shutil.rmtree(tmp_path / "units")
    (tmp_path / "units").write_text("notes")
    other = StandInExecutor()
    with pytest.raises(ValueError, match="units is not a folder, where the sweep keeps its finished units: move it away"):
        run_sweep(SweepSettings(bias_seeds=(0,), pipeline=TINY), tmp_path, other, progress=False)
    assert other.submitted == [] and (tmp_path / "units").read_text() == "notes"


def test_a_folder_made_with_other_settings_is_refused(tmp_path):
    run_sweep(SweepSettings(bias_seeds=(0,), pipeline=TINY), tmp_path, StandInExecutor(), progress=False)
    other = StandInExecutor()
    with pytest.raises(ValueError, match="other settings.*dnn_epochs"):
        run_sweep(SweepSettings(bias_seeds=(0,), pipeline=PipelineConfig(n_trajectories=3, dnn_epochs=6)), tmp_path, other, progress=False)
    assert other.submitted == []


def test_a_folder_made_by_another_version_of_the_simulator_is_refused_and_its_units_kept(tmp_path):
    settings = SweepSettings(bias_seeds=(0,), pipeline=TINY)
    run_sweep(settings, tmp_path, StandInExecutor(), progress=False)
    stamp = json.loads((tmp_path / SETTINGS_STAMP).read_text())
    assert stamp == {**json.loads(json.dumps(settings.stamp())), SOURCE_KEY: source_fingerprint().to_json()}
    stamp[SOURCE_KEY] = {"version": "0.0.9", "sha256": "0" * 64}  # as an older install stamped it
    (tmp_path / SETTINGS_STAMP).write_text(json.dumps(stamp))
    unit = (tmp_path / "units" / "bias0-seed0.json").read_bytes()
    other = StandInExecutor()
    with pytest.raises(ValueError, match=r"another version of dvrk_gym's simulator \(dvrk_gym 0\.0\.9, source sha256 000000000000;"):
        run_sweep(settings, tmp_path, other, progress=False)
    assert other.submitted == [] and (tmp_path / "units" / "bias0-seed0.json").read_bytes() == unit


def test_failed_units_are_named_the_rest_kept_and_a_rerun_retries_only_them(tmp_path):
    settings = SweepSettings(bias_seeds=(0, 1, 2), pipeline=TINY)
    with pytest.raises(SweepError, match="1 of 3 units failed: bias1-seed0 \\(RuntimeError: the worker died\\)"):
        run_sweep(settings, tmp_path, StandInExecutor(fail={(1, 0)}), progress=False)
    assert {row["bias_seed"] for row in read_rows(tmp_path / "sweep.csv")} == {"0", "2"}
    retry = StandInExecutor()
    run_sweep(settings, tmp_path, retry, progress=False)
    assert retry.submitted == ["bias1-seed0"]


def test_units_that_failed_alike_are_named_together_with_their_cause_once(tmp_path):
    """A cause every unit meets (a Dask worker of other source) was repeated once per unit."""
    settings = SweepSettings(bias_seeds=(0, 1, 2), pipeline=TINY)
    with pytest.raises(SweepError, match=r"2 of 3 units failed: bias0-seed0, bias2-seed0 \(RuntimeError: the worker died\)\. "):
        run_sweep(settings, tmp_path, StandInExecutor(fail={(0, 0), (2, 0)}), progress=False)


def test_a_grid_whose_every_unit_failed_leaves_no_table_or_figure_of_another_grid(tmp_path):
    run_sweep(SweepSettings(bias_seeds=(0, 1), pipeline=TINY), tmp_path, StandInExecutor(), progress=False)
    assert (tmp_path / "sweep_errors.png").is_file()
    with pytest.raises(SweepError, match=r"This grid's 0 finished units are in \S+units; the same call"):
        run_sweep(SweepSettings(bias_seeds=(5,), pipeline=TINY), tmp_path, StandInExecutor(fail={(5, 0)}), progress=False)
    assert not (tmp_path / "sweep.csv").exists() and not (tmp_path / "sweep_errors.png").exists()
    assert sorted(p.name for p in (tmp_path / "units").iterdir()) == ["bias0-seed0.json", "bias1-seed0.json"]  # kept


def test_a_damaged_unit_file_is_run_again(tmp_path):
    settings = SweepSettings(bias_seeds=(0, 1), pipeline=TINY)
    run_sweep(settings, tmp_path, StandInExecutor(), progress=False)
    (tmp_path / "units" / "bias1-seed0.json").write_text('{"config": ')
    (tmp_path / "units" / "bias0-seed0.json").write_text(json.dumps(stand_in_result(PipelineConfig(bias_seed=5))))
    again = StandInExecutor()
    run_sweep(settings, tmp_path, again, progress=False)
    assert sorted(again.submitted) == ["bias0-seed0", "bias1-seed0"]


def test_the_csv_has_one_row_per_cell_with_the_documented_columns(tmp_path):
    settings = SweepSettings(bias_seeds=(2, 0), calibrators=("dnn+rf", "rbt"), seeds=(0, 1), pipeline=TINY)
    result = run_sweep(settings, tmp_path, StandInExecutor(), progress=False)
    rows = read_rows(result.csv)
    assert list(rows[0]) == list(COLUMNS) and set(COLUMNS) == set(COLUMN_DOCS) and all(COLUMN_DOCS.values())
    cells = [(int(row["bias_seed"]), int(row["seed"]), row["calibrator"]) for row in rows]
    assert cells == [(b, s, c) for b in (2, 0) for s in (0, 1) for c in ("dnn+rf", "rbt")]  # the grid's order, each cell once
    expected = stand_in_result(settings.unit_config(Unit(bias_seed=2, seed=1)))["calibrators"]["rbt"]
    row = rows[3]
    assert float(row["mean_mm"]) == expected["mean_mm"] and float(row["mm_yaw45"]) == expected["settings"]["yaw 45"]["mean_mm"]
    assert float(row["px_random"]) == expected["settings"]["random"]["mean_px"]
    assert result.figure.stat().st_size > 10_000
    text = format_rows(result.rows)
    assert "dnn+rf" in text and "paper mm" in text and len(text.splitlines()) == 1 + 8 + 2 + 2


# --- real units ------------------------------------------------------------------------


class Counting:
    """Wraps an executor and counts the units it is given."""

    def __init__(self, executor):
        self.executor = executor
        self.description = executor.description
        self.count = 0

    def map_unordered(self, function, items):
        self.count += len(items)
        return self.executor.map_unordered(function, items)


def numbers(rows):
    """The rows without their wall times (which depend on the machine)."""
    return [{key: value for key, value in row.items() if key not in TIME_COLUMNS} for row in rows]


@pytest.mark.slow
def test_local_processes_and_a_dask_cluster_give_identical_numbers_and_a_resumed_sweep_runs_nothing(tmp_path):
    distributed = pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    settings = SweepSettings(bias_seeds=(0, 1), calibrators=("rbt", "dnn", "dnn+rf"), seeds=(0,), pipeline=TINY)
    with LocalExecutor(workers=2) as pool:
        local = Counting(pool)
        on_pool = run_sweep(settings, tmp_path / "local", local, progress=False)
        assert local.count == 2 and len(on_pool.computed) == 2
        resumed = Counting(pool)
        again = run_sweep(settings, tmp_path / "local", resumed, progress=False)
        assert resumed.count == 0 and again.computed == () and again.rows == on_pool.rows
    # dashboard_address ":0": any free port for the HTTP server; None still takes 8787 (distributed 2026.8), so two clusters at once warn
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster,
        DaskExecutor(cluster.scheduler_address) as dask,
    ):
        assert "2 workers" in dask.description
        on_dask = run_sweep(settings, tmp_path / "dask", dask, progress=False)
    assert len(on_dask.rows) == 6 and numbers(on_dask.rows) == numbers(on_pool.rows)
    assert (tmp_path / "local" / "sweep.csv").read_text().count("\n") == 7
    assert all(math.isfinite(row["mean_mm"]) and row["mean_mm"] > 0 for row in on_pool.rows)
    assert on_pool.rows[0]["mean_mm"] != on_pool.rows[3]["mean_mm"]  # another instrument, other numbers


@pytest.mark.slow
def test_a_unit_gives_the_calibration_table_of_the_pipeline(tmp_path, monkeypatch):
    config = dataclasses.replace(TINY, bias_seed=2, seed=1)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    orphan = scratch / f"{SCRATCH_PREFIX}{host_label()}_{_ended_pid()}_abc"  # a unit's folder, its worker killed with SIGKILL
    (orphan / "phase1.npz").parent.mkdir()
    (orphan / "phase1.npz").write_bytes(b"x")
    unit = run_unit(config)
    assert not orphan.exists() and list(scratch.glob(f"{SCRATCH_PREFIX}*")) == []  # the orphan deleted, its own folder too
    # The unit runs under torch_threads(1), the pipeline with the caller's count: the same
    # network, because DNNCalibrator trains on one thread whatever the caller's.
    with torch_threads(2):
        table = run_calibration(tmp_path, config, progress=False)["summary"]
    for name, method in (("rbt", "RBT"), ("dnn", "DNN"), ("dnn+rf", "DNN+RF")):
        assert unit["calibrators"][name]["mean_mm"] == table[method]["all settings"]["mm"]["mean"]
        assert unit["calibrators"][name]["settings"]["yaw -45"]["mean_px"] == table[method]["yaw -45"]["pixel"]["mean"]
    assert unit["config"] == {"bias_seed": 2, "seed": 1} and unit["phase1"]["kept"] > 0
    assert np.isfinite(unit["wall_s"])


def _ended_pid() -> int:
    """The pid of a process that has ended (and been reaped)."""
    process = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True)
    return int(process.stdout)


def test_scratch_folders_of_ended_processes_on_this_host_are_deleted_and_no_other(tmp_path):
    from dvrk_gym.utils.parent_watch import ScratchFolder, remove_orphaned_scratch

    ended, prefix, host = _ended_pid(), "dvrk_gym_test_", host_label()
    orphan, live = tmp_path / f"{prefix}{host}_{ended}_a", tmp_path / f"{prefix}{host}_{os.getpid()}_b"
    other_host, old_style = tmp_path / f"{prefix}elsewhere_{ended}_c", tmp_path / f"{prefix}{ended}_d"  # a shared /tmp; before hosts
    for folder in (orphan, live, other_host, old_style):
        folder.mkdir()
        (folder / "kept.txt").write_text("x")
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (tmp_path / f"{prefix}{host}_{ended}_link").symlink_to(outside, target_is_directory=True)
    (tmp_path / f"{prefix}{host}_{ended}_file").write_text("x")
    assert remove_orphaned_scratch(prefix, tmp_path) == [orphan]
    assert all(path.exists() for path in (live, other_host, old_style, outside, tmp_path / f"{prefix}{host}_{ended}_file"))
    with ScratchFolder(prefix) as folder:
        assert Path(folder).name.startswith(f"{prefix}{host}_{os.getpid()}_")
    assert not Path(folder).exists()
    with pytest.raises(ValueError, match="plain name"):
        remove_orphaned_scratch("a/b", tmp_path)


def test_a_forked_process_dropping_its_copy_of_a_scratch_folder_leaves_it_to_its_maker():
    """A TemporaryDirectory's finalizer ran in the forked child and deleted the parent's folder."""
    from dvrk_gym.utils.parent_watch import ScratchFolder

    scratch = ScratchFolder("dvrk_gym_test_")
    pid = os.fork()
    if pid == 0:  # the child: drop the copy, as an async vector env's worker may
        scratch.cleanup()
        del scratch
        gc.collect()
        os._exit(0)
    assert os.waitpid(pid, 0)[1] == 0
    assert Path(scratch.name).is_dir()
    scratch.cleanup()
    assert not Path(scratch.name).exists()


# --- the command ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--bias-seeds", "4-0"], "the range '4-0' is empty"),
        (["--calibrators", "rbt,knn"], "unknown ['knn']"),
        (["--seeds", ""], "not a non-negative number"),
        (["--scheduler", "localhost"], "the scheduler address 'localhost' is malformed (missing port"),
        (["--scheduler", "tcp://127.0.0.1:9", "--connect-timeout", "0.5"], "cannot reach a Dask scheduler at 'tcp://127.0.0.1:9'"),
        (["--workers", "0"], "--workers must be an int in [1, 1024], got 0"),
    ],
)
def test_the_command_refuses_bad_input_in_one_line_with_status_2(tmp_path, capsys, arguments, message):
    start = time.perf_counter()
    assert main(["sweep", "--out", str(tmp_path), "--no-progress", *arguments]) == 2
    error = capsys.readouterr().err
    assert error.startswith("dvrk-gym sweep: error:") and message in error and error.count("\n") == 1
    assert time.perf_counter() - start < 15
    assert not (tmp_path / "units").exists()


@pytest.mark.slow
def test_the_command_writes_the_table_and_resumes(tmp_path, capsys):
    arguments = ["sweep", "--bias-seeds", "3", "--calibrators", "dnn+rf,rbt", "--workers", "1", "--out", str(tmp_path), "--no-progress"]
    arguments += ["--trajectories", "2", "--epochs", "3", "--resolution", "640", "360"]
    assert main(arguments) == 0
    out = capsys.readouterr().out
    assert "1 units run, 0 loaded" in out and "dnn+rf" in out and "sweep.csv (2 rows)" in out
    assert [row["calibrator"] for row in read_rows(tmp_path / "sweep.csv")] == ["dnn+rf", "rbt"]
    assert (tmp_path / "sweep_errors.png").exists()
    assert main(arguments) == 0
    assert "0 units run, 1 loaded" in capsys.readouterr().out


def test_a_sweep_whose_every_unit_failed_at_first_lets_the_corrected_call_take_its_folder(tmp_path):
    """Its empty table kept the failed settings' stamp: a resolution whose grid circles are lost
    (128 x 72) left the corrected resolution refused as a sweep with other settings."""
    with pytest.raises(SweepError):
        run_sweep(SweepSettings(bias_seeds=(0,), pipeline=TINY), tmp_path, StandInExecutor(fail={(0, 0)}), progress=False)
    other = PipelineConfig(n_trajectories=3, dnn_epochs=6)
    result = run_sweep(SweepSettings(bias_seeds=(0,), pipeline=other), tmp_path, StandInExecutor(), progress=False)
    assert result.rows and len(read_rows(tmp_path / "sweep.csv")) == len(result.rows)
