"""benchmarks/bench_fidelity.py: the fidelity targets over instruments and collections, counted right."""

import json

import pytest
from benchmark_scripts import load_script

from dvrk_gym.fidelity.comparison import ComparisonRow

bench = load_script("bench_fidelity")


def _row(name: str, sim: float, passed: bool) -> ComparisonRow:
    return ComparisonRow(name=name, real=1.0, sim=sim, share=False, difference=sim, passed=passed, tolerance=0.25)


def test_the_grid_counts_each_statistics_runs_and_each_runs_statistics():
    runs = [
        bench.Run(0, 0, 10, 30, (_row("a (mm)", 1.1, True), _row("b (mm)", 2.0, False))),
        bench.Run(1, 0, 12, 30, (_row("a (mm)", 0.9, True), _row("b (mm)", 1.2, True))),
        bench.Run(1, 5, 11, 30, (_row("a (mm)", 0.2, False), _row("b (mm)", 1.0, True))),
    ]
    lines = bench.format_grid(runs).splitlines()
    assert lines[0].split()[-7:] == ["i0", "s0", "i1", "s0", "i1", "s5", "met"]
    assert lines[1].split()[-4:] == ["1.10", "0.90", "0.20*", "2/3"]
    assert lines[2].split()[-4:] == ["2.00*", "1.20", "1.00", "2/3"]
    assert "instrument 0, collection seed 0: 1 of 2 statistics within target (10 of 30 rows kept)" in lines
    assert "instrument 1, collection seed 5: 1 of 2 statistics within target (11 of 30 rows kept)" in lines
    assert lines[-1].startswith("0 of 2 statistics within target in every run")
    with pytest.raises(ValueError, match="different statistics"):
        bench.format_grid([runs[0], bench.Run(2, 0, 1, 2, (_row("a (mm)", 1.0, True), _row("c", 1.0, True)))])


def test_it_runs_a_small_grid_and_writes_what_it_printed(tmp_path, capsys):
    bench.main(["--bias-seeds", "1", "--trajectories", "6", "--resolution", "640", "360", "--out", str(tmp_path)])
    printed = capsys.readouterr().out
    written = json.loads((tmp_path / bench.JSON_NAME).read_text())
    (run,) = written["runs"]
    assert (run["bias_seed"], run["seed"]) == (1, 0)
    assert run["passed"] == sum(statistic["passed"] for statistic in run["statistics"]) > 0
    assert f"instrument 1, collection seed 0: {run['passed']} of {len(run['statistics'])} statistics within target" in printed
    assert written["settings"] == {"bias": "paper", "trajectories": 6, "camera_resolution": [640, 360]}
