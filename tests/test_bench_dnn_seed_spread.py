"""benchmarks/dnn_seed_spread.py: the run's own seed gives back its calibrators, other seeds differ, the printout, bad flags."""

import shutil

import gymnasium as gym
import numpy as np
import pytest
from benchmark_scripts import ScriptRun, load_script, run_script, script_path

from dvrk_gym.calibration.loading import load_calibrator
from dvrk_gym.calibration.phase1 import Phase1Data
from dvrk_gym.calibration.phase2 import Phase2Data
from dvrk_gym.calibration.pipeline import PipelineConfig, read_pipeline_settings

dnn_seed_spread = load_script("dnn_seed_spread")
SCRIPT = script_path("dnn_seed_spread")


def _run(*args: str) -> ScriptRun:
    return run_script(SCRIPT, *args)


def test_the_spread_is_printed_per_setting_with_the_seeds_that_meet_the_targets(capsys):
    results = {
        0: dnn_seed_spread.SeedResult({"DNN": np.array([1.0, 1.0, 1.0, 1.0, 3.5, 1.0]), "DNN+RF": np.full(6, 0.9)}, 4.0, 0.5),
        4: dnn_seed_spread.SeedResult({"DNN": np.array([1.0, 1.0, 1.0, 1.0, 2.5, 1.0]), "DNN+RF": np.full(6, 1.7)}, 2.0, -0.5),
    }
    dnn_seed_spread.print_spread(results)
    lines = capsys.readouterr().out.splitlines()
    pushes = lines.index("Phase II pushes (mm): the mean y's spread over the yaws; x after the move to the next row minus along a row")
    assert [line.split() for line in lines[pushes + 2 : pushes + 5]] == [
        ["0", "4.00", "0.50"],
        ["4", "2.00", "-0.50"],
        ["mean", "3.00", "0.00"],
    ]
    assert [line.split() for line in lines[-2:]] == [["real,", "round", "0", "1.03", "-0.99"], ["real,", "round", "1", "0.68", "-0.42"]]
    lines = lines[:pushes]
    dnn = lines[: lines.index("DNN+RF: mean touch error (mm) per setting")]
    rows = {line.split()[0]: [float(v) for v in line.split()[1:]] for line in dnn[2:8]}
    assert rows["0"][4] == 3.5 and rows["0"][-1] == pytest.approx(8.5 / 6, abs=0.005)
    assert rows["mean"][4] == 3.0 and rows["sd"][4] == 0.5 and rows["min"][4] == 2.5 and rows["max"][4] == 3.5
    assert dnn[-1] == "  every cell at most 3.0 mm: 1 of 2 seeds [4]"
    assert lines[-1] == "  every cell at most 1.6 mm: 1 of 2 seeds [0]"


@pytest.mark.parametrize("seeds", [["1", "1"], ["-1"], ["0", "4294967296"]])
def test_it_refuses_repeated_or_negative_seeds(seeds, tmp_path):
    result = _run("--calibration", str(tmp_path), "--seeds", *seeds)
    assert result.returncode == 2 and "--seeds takes 1 to 64 distinct seeds in 0-4294967295" in result.stderr.splitlines()[-1]


def test_it_refuses_a_folder_no_calibration_made(tmp_path):
    result = _run("--calibration", str(tmp_path))
    assert result.returncode == 2 and "not a calibration run folder" in result.stderr.splitlines()[-1]


def test_it_refuses_a_calibration_stopped_before_its_phase_i_ended(small_calibration, tmp_path):
    stopped = tmp_path / "stopped"
    stopped.mkdir()
    shutil.copy(small_calibration / "pipeline_config.json", stopped)
    result = _run("--calibration", str(stopped))
    assert result.returncode == 2 and "holds no phase1.npz" in result.stderr.splitlines()[-1]


def test_the_runs_own_seed_gives_back_its_network_and_forests_and_another_seed_differs(small_calibration):
    config = PipelineConfig.from_settings(read_pipeline_settings(small_calibration))
    phase1 = Phase1Data.load(small_calibration / "phase1.npz")
    X = phase1.cleaned().X
    made = {name: load_calibrator(small_calibration, name)[0].predict(X) for name in ("dnn", "dnn+rf")}
    remade = {}
    for seed in (config.seed, config.seed + 1):
        grid = gym.make("dvrk_gym/GridTouch-v0", **config.env_kwargs())
        try:
            calibrators, phase2 = dnn_seed_spread.seed_calibrators(grid, phase1, config, seed)
            remade[seed] = {name: model.predict(X) for name, model in calibrators.items()}
            if seed == config.seed:
                assert np.array_equal(phase2.corrected, Phase2Data.load(small_calibration / "phase2.npz").corrected)
        finally:
            grid.close()
    for name, method in (("dnn", "DNN"), ("dnn+rf", "DNN+RF")):
        assert np.array_equal(remade[config.seed][method], made[name])  # bit for bit: the calibration's own
        assert not np.allclose(remade[config.seed + 1][method], made[name], rtol=0.0, atol=1e-6)
