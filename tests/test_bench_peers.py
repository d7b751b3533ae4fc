"""benchmarks/bench_peers.py: it runs beside panda-gym, and says how to install it when it is missing."""

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from benchmark_scripts import load_script

from dvrk_gym.sim.endoscope.fragment_detection import FragmentObserver
from dvrk_gym.sim.physics.client import Physics

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "bench_peers.py"

# Runs the script with panda_gym made unimportable, as in an environment without the extra.
WITHOUT_PANDA_GYM = f"""
import runpy, sys
class Missing:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "panda_gym":
            raise ModuleNotFoundError(f"No module named {{name!r}}")
sys.meta_path.insert(0, Missing())
sys.argv = [{str(SCRIPT)!r}, "--rounds", "1"]
runpy.run_path({str(SCRIPT)!r}, run_name="__main__")
"""


def test_without_panda_gym_it_exits_non_zero_and_names_the_install_command():
    result = subprocess.run([sys.executable, "-c", WITHOUT_PANDA_GYM], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert 'pip install -e ".[bench]"' in result.stderr and "pip install panda-gym==3.0.7" in result.stderr
    assert result.stdout == ""  # nothing timed


@pytest.mark.slow
def test_it_times_all_six_rows_and_prints_their_ratio_to_panda_reach_and_the_physics_they_step():
    pytest.importorskip("panda_gym")
    arguments = ["--steps", "20", "--picks", "1", "--delta-steps", "3", "--rounds", "2", "--resolution", "320", "180"]
    result = subprocess.run([sys.executable, str(SCRIPT), *arguments], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()  # panda-gym's PyBullet prints its argv lines first
    header = next(i for i, line in enumerate(lines) if line.startswith("env (random actions"))
    rows = {line.rsplit(maxsplit=6)[0]: line.rsplit(maxsplit=6)[1:] for line in lines[header + 1 : header + 7]}
    names = [
        "GridTouch-v0",
        "CalibrationExploration-v0",
        "Debridement-v0",
        "Debridement-v0 (delta)",
        "PandaReach-v3",
        "PandaPickAndPlace-v3",
    ]
    assert list(rows) == names
    assert rows["PandaReach-v3"][1:4] == ["1.00", "(1.00-1.00)", "1.00"]  # each round's ratio to itself
    for name, (rate, ratio, spread, cpu_ratio, clock, physics) in rows.items():
        low, high = (float(v) for v in spread.strip("()").split("-"))
        assert float(rate) > 0.0 and low <= float(ratio) <= high and float(cpu_ratio) > 0.0 and float(clock) > 0.0, name
        kinematic = name in ("GridTouch-v0", "CalibrationExploration-v0")  # no stepSimulation along their moves
        assert (float(physics) == 0.0) == kinematic, (name, physics)
    for name in ("Debridement-v0 (delta)", "PandaReach-v3"):  # every 0.1 s (0.04 s) of robot time is stepped
        assert rows[name][4] == rows[name][5], name
    assert float(rows["Debridement-v0"][5]) < float(rows["Debridement-v0"][4])  # a pick's free-space moves are placed at once


def test_the_pick_parts_benchmark_times_every_part_of_a_pick():
    """benchmarks/bench_pick_parts.py: every part it names was called and timed (a renamed method fails here)."""
    script = ROOT / "benchmarks" / "bench_pick_parts.py"
    arguments = ["--trials", "1", "--resolution", "320", "180"]
    result = subprocess.run([sys.executable, str(script), *arguments], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("part (indented"))
    rows = {line.split()[0]: line.split()[1:] for line in lines[header + 1 :]}
    assert len(rows) == 14 and rows["DebridementEnv._step_episode"][2] == "100%"
    for name, (ms, calls, share) in rows.items():
        assert float(ms) > 0.0 and int(calls) > 0 and share.endswith("%"), name
    assert int(rows["Physics.step"][1]) > 100 * int(rows["DebridementEnv._step_episode"][1])  # hundreds of steps a pick


def test_the_pick_benchmarks_what_ifs_change_the_simulation_as_they_say(monkeypatch):
    """bench_pick_parts.py's what-ifs: the physics steps every S seconds; each fragment is
    located by its coarse blob alone, within a pixel of where its full-resolution window puts it."""
    parts = load_script("bench_pick_parts")
    for name in ("_coarse_blobs", "_fine_blob", "observe"):  # restored after the test
        monkeypatch.setattr(FragmentObserver, name, getattr(FragmentObserver, name))
    monkeypatch.setattr(Physics, "__init__", Physics.__init__)
    seen: list[np.ndarray] = []
    observe = FragmentObserver.observe

    def recording(self, client, noise_rng=None):  # type: ignore[no-untyped-def]
        detections = observe(self, client, noise_rng)
        seen.append(np.array([[*d.left.centroid, *d.right.centroid, d.left.angle_rad] for d in detections]))
        return detections

    monkeypatch.setattr(FragmentObserver, "observe", recording)

    def fragments() -> np.ndarray:
        """(u, v) left, (u, v) right (px) and the left ellipse's angle (rad) of each fragment seen after a reset."""
        env = gym.make("dvrk_gym/Debridement-v0")
        try:
            env.reset(seed=3)
        finally:
            env.close()
        return seen[-1]

    full = fragments()
    parts.what_if_coarse_only()
    coarse = fragments()
    assert coarse.shape == full.shape and len(full) > 0
    difference = np.abs(coarse - full)
    assert 0.0 < difference[:, :4].max() < 1.0  # px at 1920 x 1080: moved, by less than a pixel
    assert difference[:, 4].max() < 0.05  # rad: the seed's angle, which the grasp turns to
    parts.what_if_physics_step(1.0 / 120.0)
    physics = Physics()
    try:
        assert physics.time_step_s == 1.0 / 120.0
    finally:
        physics.close()
