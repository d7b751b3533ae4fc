"""benchmarks/fidelity_visibility.py: its instruments are what it says, and its tables add up."""

import subprocess
import sys

import numpy as np
from benchmark_scripts import ROOT, load_script, script_path

from dvrk_gym.envs import grid_touch
from dvrk_gym.sim.endoscope.camera import WORKSPACE_CENTER_M, default_camera_pose
from dvrk_gym.sim.robot import kinematics as kin

SCRIPT = script_path("fidelity_visibility")
visibility = load_script("fidelity_visibility")


def test_an_orbited_camera_keeps_its_distance_and_turns_by_the_angle():
    centre = np.asarray(WORKSPACE_CENTER_M)
    before = default_camera_pose()
    after = visibility.orbited_camera((1.0, 0.0, 0.0), 20.0)
    assert np.isclose(np.linalg.norm(after[:3, 3] - centre), np.linalg.norm(before[:3, 3] - centre), rtol=1e-12)
    turn = after[:3, :3] @ before[:3, :3].T  # the camera turned by 20 degrees about base x
    np.testing.assert_allclose(turn, kin.rotation_x(np.deg2rad(20.0)), atol=1e-12)
    # The ray from the camera to the centre turns with the view: the centre stays where it was in the image.
    local = lambda pose: pose[:3, :3].T @ (centre - pose[:3, 3])  # noqa: E731
    np.testing.assert_allclose(local(after), local(before), atol=1e-12)
    np.testing.assert_allclose(visibility.orbited_camera((0.0, 1.0, 0.0), 0.0), before, atol=1e-15)


def test_the_touch_pitch_offset_moves_the_touches_pitch_and_is_undone():
    position = np.array([0.04, 0.04, -0.15])
    original = grid_touch.tool_pose(position, np.pi / 2).copy()
    with visibility.touch_pitch_offset(np.deg2rad(-10.0)):
        moved = grid_touch.tool_pose(position, np.pi / 2)
        _, pitch, _ = kin.euler_from_pose(moved)
        assert abs(np.rad2deg(pitch) - 0.0) < 1e-9  # the paper's 10 degrees at yaw 90, minus 10
    np.testing.assert_array_equal(grid_touch.tool_pose(position, np.pi / 2), original)
    assert kin.paper_pitch_roll(np.pi / 2)[0] == np.deg2rad(10.0)


def test_it_prints_every_part_and_the_hidden_rows_add_up():
    arguments = ["--trajectories", "2", "--every", "25"]
    result = subprocess.run([sys.executable, str(SCRIPT), *arguments], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("1. Kept rows"))
    real_rows = [int(line.split()[1]) for line in lines[first + 2 : first + 7]]
    assert real_rows == [251, 583, 552, 379, 174]  # the authors' 1939 rows per nearest yaw
    second = next(i for i, line in enumerate(lines) if line.startswith("2. Raw rows"))
    header = next(i for i in range(second, len(lines)) if lines[i].startswith("yaw   raw"))
    for line in lines[header + 1 : header + 6]:
        if int(line.split()[1]) == 0:
            continue
        seen_and_causes = line.split()[3:4] + line.split()[5:]  # skip the angle column
        values = [float(v) for v in seen_and_causes]
        assert abs(sum(values) - 1.0) < 0.05, line  # seen, or hidden by one named cause (each rounded to 0.01)
    angles = next(i for i, line in enumerate(lines) if line.startswith("   The jaws' angle from the line of sight"))
    for line in lines[angles + 2 : angles + 7]:
        real_part, sim_part = line.split("|")
        real_values = [float(v) for v in real_part.split()[1:]]
        assert len(real_values) == 4 and real_values[0] <= real_values[1] <= real_values[2], line  # percentiles, then a share
        assert 0.0 <= real_values[3] <= 1.0 and (sim_part.split() == ["none"] or len(sim_part.split()) == 4), line
    third = next(i for i, line in enumerate(lines) if line.startswith("3. Seen rows"))
    labels = [line.split("  ")[0] for line in lines[third + 1 :]]
    assert labels[0].startswith("real") and labels[1].startswith("as identified") and len(labels) == 14
