"""benchmarks/pick_depths.py: the heights it measures, against a calibrator that knows the truth, and a run."""

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from benchmark_scripts import ROOT, load_script, run_script, script_path
from conftest import SMALL, tool_to_tip_m

import dvrk_gym  # noqa: F401  (registers the envs)
from dvrk_gym.calibration.policy import calibrator_input
from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.sim.robot import kinematics as kin

pick_depths = load_script("pick_depths")
SCRIPT = script_path("pick_depths")


class TrueCamera:
    """A calibrator for the unbiased instrument that knows the camera: the command that puts the
    closed jaw tip on the camera-frame point, less ``drop_m`` of height (metres)."""

    def __init__(self, env: gym.Env, drop_m: float) -> None:
        self.camera = env.unwrapped.world.camera
        self.drop_m = drop_m

    def predict(self, X: np.ndarray) -> np.ndarray:
        point = self.camera.to_world(X[:, :3])[0] - [0.0, 0.0, self.drop_m]
        return (point - tool_to_tip_m(float(X[0, 3])))[None]


@pytest.mark.parametrize("drop_mm", [0.0, 3.0])
def test_a_calibrator_aiming_at_the_seen_point_gives_its_heights_back(drop_mm):
    env = gym.make("dvrk_gym/Debridement-v0", bias="none", camera_resolution=SMALL)
    try:
        rows = pick_depths.first_picks(env, TrueCamera(env, 1e-3 * drop_mm), trials=2)
    finally:
        env.close()
    seen, centre, aimed, follows, under, slide = rows.T  # mm
    assert np.all(seen > centre) and np.all(centre > 0.5)  # the endoscope sees the top of the fragment
    np.testing.assert_allclose(aimed, seen - drop_mm, atol=0.05)  # the tip where it was sent
    np.testing.assert_allclose(follows, 2.0, atol=0.05)  # a map that follows height
    np.testing.assert_allclose(under, np.maximum(-(aimed - 2.0), 0.0), atol=1e-9)  # the pick goes 2 mm under its target
    if not drop_mm:
        assert np.all(under == 0.0) and np.all(slide == 0.0)  # over the paper: nothing slides
        return
    assert np.all(under > 0.5)
    # what a pick at that command does: the jaws slide by the printed slide from where the rigid paper leaves them
    grips = {}
    for contact in ("rigid", "compliant"):
        env = gym.make("dvrk_gym/Debridement-v0", bias="none", camera_resolution=SMALL, contact=contact)
        try:
            observation, _ = env.reset(seed=0)
            command = TrueCamera(env, 1e-3 * drop_mm).predict(calibrator_input(*fragment_target(observation)))[0]
            _, _, _, _, info = env.step(np.array([*command, kin.nearest_paper_yaw(fragment_target(observation)[1])], dtype=np.float32))
            grips[contact] = np.asarray(info["true_tip_at_grip"])
        finally:
            env.close()
    assert 1e3 * np.linalg.norm(grips["compliant"][:2] - grips["rigid"][:2]) == pytest.approx(slide[0], abs=0.1)


def test_it_prints_a_row_per_fragment_and_calibrator(small_calibration):
    arguments = ["--calibration", str(small_calibration), "--calibrators", "rbt", "dnn", "--trials", "1"]
    result = subprocess.run([sys.executable, str(SCRIPT), *arguments], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    rows = [line.split() for line in result.stdout.splitlines()[2:]]
    assert [row[:2] for row in rows] == [["pumpkin_seed", "RBT"], ["pumpkin_seed", "DNN"], ["raisin", "RBT"], ["raisin", "DNN"]]
    assert all(len(row) == 8 for row in rows)
    assert float(rows[0][5]) == pytest.approx(2.0, abs=0.5)  # a rigid map follows a raised point (its fit scales it a little)


def test_it_refuses_a_folder_no_calibration_made(tmp_path):
    result = run_script(SCRIPT, "--calibration", str(tmp_path))
    assert result.returncode == 2 and "not a calibration run folder" in result.stderr.splitlines()[-1]
