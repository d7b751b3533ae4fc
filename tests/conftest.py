"""Shared fixtures: small images keep the env tests fast; full-HD tests ask for it."""

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import dvrk_gym  # noqa: F401  (registers the environments)

SMALL = (640, 360)
ENV_IDS = list(dvrk_gym.ENV_IDS)
"""Every registered env (test_envs_common.py runs its shared behaviours on each)."""
ENV_IDS_BUT_DEBRIDEMENT = [env_id for env_id in ENV_IDS if env_id != "dvrk_gym/Debridement-v0"]
"""For the shared tests that tests/test_env_debridement*.py already run on Debridement-v0 in
both action modes (the checkers, determinism with the cable history, across processes):
its picks are the suite's slowest steps."""


@pytest.fixture
def make_env():
    """Make environments that are closed after the test."""
    made = []

    def _make(env_id: str, **kwargs):
        kwargs.setdefault("camera_resolution", SMALL)
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env

    yield _make
    for env in made:
        env.close()


def json_from_fresh_process(code: str):
    """Run ``code`` in a new Python process (in the tests' folder) and parse the JSON it prints last."""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=Path(__file__).parent)
    return json.loads(result.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def tiny_reproduction(tmp_path_factory):
    """``dvrk-gym reproduce`` with the tiny profile (:data:`dvrk_gym.reproduce.TINY`: every task
    of the quick run on budgets that keep the suite short), seed 0, one worker, made once per
    test process: the reference the tests of workers, executors and resuming compare with.
    Read it; do not write to it (copy the folder first)."""
    from dvrk_gym.reproduce import TINY, ReproduceConfig, run_reproduce

    return run_reproduce(ReproduceConfig(out=tmp_path_factory.mktemp("tiny_reproduction") / "run", profile=TINY, workers=1, progress=False))


@pytest.fixture(scope="session")
def small_calibration(tmp_path_factory) -> Path:
    """A ``dvrk-gym calibrate`` folder made once per test process (2 trajectories, 20 epochs,
    640 x 360): for the benchmark scripts that read a calibration run. Read it; do not write to it."""
    folder = tmp_path_factory.mktemp("small_calibration") / "cal"
    small = ["--trajectories", "2", "--epochs", "20", "--resolution", "640", "360", "--out", str(folder), "--no-progress"]
    made = subprocess.run(
        [sys.executable, "-m", "dvrk_gym.cli.main", "calibrate", *small],
        cwd=Path(__file__).parents[1],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert made.returncode == 0, made.stderr[-2000:]
    return folder


def tool_to_tip_m(yaw: float):
    """Where the closed jaw tip lies from the tool position commanded at ``yaw`` (rad), metres,
    without cable bias: what a perfect calibration subtracts from a target (tests only)."""
    from dvrk_gym.envs.grid_touch import tool_pose
    from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M
    from dvrk_gym.sim.robot import ik
    from dvrk_gym.sim.robot import kinematics as kin

    reference = tool_pose(WORKSPACE_CENTER_M + [0.0, 0.0, 0.01], yaw)
    return kin.touch_point(ik.inverse_kinematics(reference)) - reference[:3, 3]


@pytest.fixture
def unseen_phase1():
    """A Phase I collection of ``n`` rows in which the camera never saw the marker (none kept)."""
    import numpy as np

    from dvrk_gym.calibration.phase1 import Phase1Data

    def make(n: int) -> Phase1Data:
        return Phase1Data(
            reported_position=np.zeros((n, 3)),
            orientation=np.zeros((n, 3)),
            left_px=np.full((n, 2), np.nan),
            right_px=np.full((n, 2), np.nan),
            areas_px=np.zeros((n, 2)),
            camera_position=np.full((n, 3), np.nan),
            trajectory=np.zeros(n, dtype=int),
            kept=np.zeros(n, dtype=bool),
        )

    return make
