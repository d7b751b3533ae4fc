"""benchmarks/identify_tape_shift.py: its crossing, its patch of the tape detector, its flags."""

import numpy as np
import pytest
from benchmark_scripts import load_script, run_script, script_path

from dvrk_gym.sim import identified
from dvrk_gym.sim.endoscope.baseline import true_baseline_m
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

shift_script = load_script("identify_tape_shift")
SCRIPT = script_path("identify_tape_shift")


def test_the_crossing_is_linear_between_the_two_candidates_around_the_target():
    shifts, heights = np.array([3.0, 0.0, 2.0, 4.0]), np.array([-8.4, -1.7, -6.1, -10.8])  # unsorted on purpose
    assert shift_script.crossing(shifts, heights, -7.2) == pytest.approx(2.0 + (-7.2 + 6.1) / (-8.4 + 6.1))
    assert shift_script.crossing(shifts, heights, -1.7) == 0.0
    with pytest.raises(ValueError, match="bracket"):
        shift_script.crossing(shifts, heights, -12.0)


def test_the_tape_shift_reaches_every_new_world_and_is_undone():
    small = WorldConfig(bias="none", camera_resolution=(320, 180))
    with shift_script.tape_shift(1.5):
        world = DvrkWorld(small)
        try:
            assert world.config.marker_noise.right_shift_px == 1.5
            assert world.camera.baseline_m == true_baseline_m(1.5)
            assert world.config.marker_noise.miss_probability == small.marker_noise.miss_probability  # the rest kept
        finally:
            world.close()
    world = DvrkWorld(small)
    try:
        assert world.config.marker_noise.right_shift_px == identified.TAPE_RIGHT_SHIFT_PX
        assert world.camera.baseline_m == true_baseline_m(identified.TAPE_RIGHT_SHIFT_PX)
    finally:
        world.close()


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--shifts", "0", "30"], "at least two distinct values in"),
        (["--shifts", "2", "2"], "at least two distinct"),
        (["--check-seeds", "-1"], "must be >= 0"),
    ],
)
def test_it_refuses_bad_flags_before_any_work(flags, message):
    result = run_script(SCRIPT, *flags)
    assert result.returncode == 2
    assert message in result.stderr.splitlines()[-1]
