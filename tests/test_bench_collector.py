"""benchmarks/fidelity_collector.py: its collector what-ifs change what they say and are undone."""

import subprocess
import sys

import numpy as np
import pytest
from benchmark_scripts import ROOT, load_script, script_path

from dvrk_gym import paper
from dvrk_gym.calibration import phase1
from dvrk_gym.envs import exploration

collector_script = load_script("fidelity_collector")
SCRIPT = script_path("fidelity_collector")


def test_the_collector_what_if_steps_and_heights_apply_and_are_undone():
    before = (exploration.SAFE_Z_M, phase1.SAFE_Z_M, phase1.PaperExplorationPolicy)
    with collector_script.collector(0.002, -0.147, -0.151):
        policy = phase1.PaperExplorationPolicy(seed=0)
        assert policy.step_m == 0.002 and isinstance(policy, before[2])
        assert exploration.workspace_corners()[:, 2].tolist() == [-0.147] * 4  # the corners sit at the middle of the band
        position = policy._draw_target()
        assert position[2] == -0.151
        assert phase1.PaperExplorationPolicy(seed=0, step_m=0.003).step_m == 0.003  # an explicit step still wins
    assert (exploration.SAFE_Z_M, phase1.SAFE_Z_M, phase1.PaperExplorationPolicy) == before
    assert phase1.PaperExplorationPolicy(seed=0).step_m == paper.PHASE1_STEP_M
    with collector_script.collector(0.001, None, None):
        assert before[:2] == (exploration.SAFE_Z_M, phase1.SAFE_Z_M)
    with pytest.raises(ValueError, match="step_m"), collector_script.collector(0.0, None, None):
        pass
    assert phase1.PaperExplorationPolicy is before[2]


def test_it_prints_the_fidelity_table_of_the_changed_collection_and_refuses_bad_values():
    small = ["--trajectories", "6", "--resolution", "640", "360"]
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--step-mm", "2", "--corner-mm", "5", "--target-mm", "1", *small],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    first = result.stdout.splitlines()[0]
    height = float(first.split("report ")[1].split(" mm")[0])
    assert -160.0 < height < -145.0 and "step 2 mm, corners 5.0, targets 1.0" in first
    assert "statistics within target" in result.stdout.splitlines()[-1]
    for bad in (["--step-mm", "0"], ["--corner-mm", "nan"], ["--target-mm", "50"]):
        refused = subprocess.run([sys.executable, str(SCRIPT), *bad], cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert refused.returncode == 2 and "must be in" in refused.stderr, bad


def test_the_pushed_jaws_lie_where_the_phase2_corrections_put_them():
    height = collector_script.pushed_jaws_height(0, (640, 360))
    assert np.isfinite(height) and -0.16 < height < -0.145
