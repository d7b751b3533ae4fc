"""benchmarks/fidelity_collector.py: its collector what-ifs change what they say and are undone."""

import subprocess
import sys

import pytest
from benchmark_scripts import ROOT, load_script, run_script, script_path

from dvrk_gym import paper
from dvrk_gym.calibration import phase1
from dvrk_gym.calibration.datasets import load_paper_phase1
from dvrk_gym.envs import exploration
from dvrk_gym.sim import identified
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

collector_script = load_script("fidelity_collector")
SCRIPT = script_path("fidelity_collector")


def test_the_collector_what_if_steps_and_heights_apply_and_are_undone():
    before = (exploration.CORNER_Z_M, phase1.TARGET_Z_M, phase1.PaperExplorationPolicy)
    with collector_script.collector(0.001, -0.150, -0.151):
        policy = phase1.PaperExplorationPolicy(seed=0)
        assert policy.step_m == 0.001 and isinstance(policy, before[2])
        assert exploration.workspace_corners()[:, 2].tolist() == [-0.150] * 4
        assert policy._draw_target()[2] == -0.151
        assert phase1.PaperExplorationPolicy(seed=0, step_m=0.003).step_m == 0.003  # an explicit step still wins
    assert (exploration.CORNER_Z_M, phase1.TARGET_Z_M, phase1.PaperExplorationPolicy) == before
    assert phase1.PaperExplorationPolicy(seed=0).step_m == paper.PHASE1_STEP_M
    with collector_script.collector(0.002, None, None):
        assert before[:2] == (exploration.CORNER_Z_M, phase1.TARGET_Z_M)
    with pytest.raises(ValueError, match="step_m"), collector_script.collector(0.0, None, None):
        pass
    assert phase1.PaperExplorationPolicy is before[2]


def test_it_prints_the_fidelity_table_of_the_changed_collection_and_refuses_bad_values():
    small = ["--trajectories", "6", "--resolution", "640", "360"]
    result = subprocess.run(
        [
            sys.executable,
            str(SCRIPT),
            "--step-mm",
            "1",
            "--corner-mm",
            "2.6",
            "--target-mm",
            "2.6",
            "--no-search-box",
            "--miss-probability",
            "0.29",
            *small,
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    first = result.stdout.splitlines()[0]
    height = float(first.split("report ")[1].split(" mm")[0])
    assert -160.0 < height < -145.0 and "step 1 mm, corners 2.6, targets 2.6" in first
    lines = result.stdout.splitlines()
    assert lines[1] == "the tape detector searches the whole image and misses 0.29 of the images"
    assert "statistics within target" in lines[-3] and lines[-2].startswith("sd: standard error from a moving-block bootstrap")
    assert lines[-1].startswith("kept rows outside the authors' search boxes: real 0.000, simulated ")
    refusals = (
        (["--step-mm", "0"], "--step-mm must be in"),
        (["--corner-mm", "nan"], "--corner-mm must be in"),
        (["--target-mm", "50"], "--target-mm must be in"),
        (["--miss-probability", "1"], "--miss-probability must be in"),
        (["--out", "x"], "give --calibrate too"),
        (["--calibrate", "--out", str(ROOT)], "is not empty"),
    )
    for bad, message in refusals:
        refused = run_script(SCRIPT, *bad)
        assert refused.returncode == 2 and message in refused.stderr, bad


def test_the_collectors_paper_is_where_the_identified_instrument_reports_its_pushed_jaws():
    """The corners' and targets' heights are measured from PAPER_REPORTED_Z_M: instrument 0's
    pushed jaws lie there (to 0.1 mm), the others' within 0.5 mm."""
    heights = [collector_script.pushed_jaws_height(seed, (640, 360)) for seed in (0, 1, 2)]
    assert abs(heights[0] - exploration.PAPER_REPORTED_Z_M) < 1e-4
    assert all(abs(height - exploration.PAPER_REPORTED_Z_M) < 5e-4 for height in heights)
    assert abs(exploration.CORNER_Z_M - exploration.PAPER_REPORTED_Z_M - 0.005) < 1e-12
    assert abs(phase1.TARGET_Z_M - exploration.PAPER_REPORTED_Z_M - 0.001) < 1e-12


def test_the_detector_what_if_searches_the_whole_image_and_is_undone():
    with collector_script.detector(search_boxes=False, miss_probability=0.29):
        world = DvrkWorld(WorldConfig(camera_resolution=(320, 180)))
        try:
            assert world.config.marker_noise.search_boxes_px is None and world.config.marker_noise.miss_probability == 0.29
        finally:
            world.close()
    world = DvrkWorld(WorldConfig(camera_resolution=(320, 180)))
    try:
        assert world.config.marker_noise.search_boxes_px == paper.MARKER_SEARCH_BOXES_PX
        assert world.config.marker_noise.miss_probability == identified.MARKER_DETECTION_NOISE.miss_probability
    finally:
        world.close()
    with pytest.raises(ValueError, match="miss_probability"), collector_script.detector(search_boxes=True, miss_probability=1.0):
        pass


def test_no_real_row_lies_outside_the_boxes_and_a_row_below_them_does():
    X, _ = load_paper_phase1()
    assert collector_script.outside_boxes_share(X) == 0.0
    beyond = X[:2].copy()
    beyond[0, 1] += 0.01  # 10 mm along the camera's y: from v = 713 to about 840 px, past the boxes' 800
    assert collector_script.outside_boxes_share(beyond) == 0.5
