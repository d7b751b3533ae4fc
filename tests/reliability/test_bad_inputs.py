"""Every constructor argument, option and action checked by type and range; no silent coercion.

Hypothesis draws wrong types (text, bools, complex numbers, None, lists), non-finite and
out-of-range numbers for each field of each configuration; each must be refused with a
ValueError that names the field, and each value in range accepted as it was given.
"""

import copy
import math
import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dvrk_gym.baselines.training import TrainConfig
from dvrk_gym.calibration.pipeline import PipelineConfig
from dvrk_gym.cli.main import build_parser, main
from dvrk_gym.cli.options import forget_created_folders, remove_empty_created_folders, writable_folder
from dvrk_gym.envs.base import check_action
from dvrk_gym.envs.debridement_config import DebridementConfig
from dvrk_gym.envs.exploration import ExplorationConfig
from dvrk_gym.envs.grid_touch import GridTouchConfig
from dvrk_gym.envs.picks import PickTiming
from dvrk_gym.reproduce.profiles import Profile
from dvrk_gym.sim.robot.motion import MotionLimits
from dvrk_gym.sim.table.grasp import GripperConfig
from dvrk_gym.sim.world import WorldConfig
from dvrk_gym.utils.run_folder import RunFolder, RunFolderBusy

FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

NOT_A_NUMBER = st.one_of(
    st.text(max_size=5),
    st.booleans(),
    st.complex_numbers(allow_nan=False, allow_infinity=False).filter(lambda z: z.imag != 0),
    st.none(),
    st.lists(st.integers(), max_size=3),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), "8", "0.1"]),
)
NOT_AN_INT = st.one_of(NOT_A_NUMBER, st.floats(allow_nan=False, allow_infinity=False))

OPEN_0 = -0.0
"""Marks a range open at 0: (0, high]."""
# (config class, field, low, high): float fields; a value outside [low, high] must be refused.
FLOAT_FIELDS = [
    (GridTouchConfig, "distance_threshold_m", 0.0, 0.05),
    (GridTouchConfig, "approach_height_m", 0.0, 0.05),
    (GridTouchConfig, "correction_noise_m", 0.0, 0.01),
    (GridTouchConfig, "pixel_noise_px", 0.0, 50.0),
    (DebridementConfig, "control_period_s", OPEN_0, 10.0),
    (DebridementConfig, "max_delta_m", OPEN_0, 0.05),
    (DebridementConfig, "max_delta_jaw_rad", OPEN_0, math.pi),
    (DebridementConfig, "delta_yaw_rad", -math.pi / 2, math.pi / 2),
    (GripperConfig, "grip_force_n", OPEN_0, 100.0),
    (GripperConfig, "jaw_friction", 0.0, 10.0),
    (GripperConfig, "pierce_max_angle_rad", 0.0, math.pi / 2),
    (PickTiming, "grip_depth_m", 0.0, 0.1),
    (PickTiming, "drop_dwell_s", 0.0, 60.0),
    (MotionLimits, "max_speed_m_s", OPEN_0, 1.0),
    (MotionLimits, "settle_time_s", 0.0, 10.0),
    (WorldConfig, "pixel_noise_px", 0.0, 50.0),
]
INT_FIELDS = [
    (DebridementConfig, "max_picks", 1, 64),
    (DebridementConfig, "max_steps", 1, 1_000_000),
    (ExplorationConfig, "max_steps", 1, 100_000),
    (GridTouchConfig, "bias_seed", 0, 2**31 - 1),
    (GripperConfig, "grasp_steps", 1, 10_000),
    (WorldConfig, "bias_seed", 0, 2**31 - 1),
    (PipelineConfig, "n_trajectories", 1, 10_000),
    (PipelineConfig, "dnn_epochs", 1, 10**7),
    (PipelineConfig, "seed", 0, 2**31 - 1),
]


def _field_ids(fields):
    return [f"{klass.__name__}.{name}" for klass, name, *_ in fields]


@pytest.mark.parametrize(("klass", "name", "low", "high"), FLOAT_FIELDS, ids=_field_ids(FLOAT_FIELDS))
@FUZZ
@given(data=st.data())
def test_float_fields_refuse_wrong_types_and_values_out_of_range(klass, name, low, high, data):
    open_low = math.copysign(1.0, low) < 0 and low == 0.0
    too_low = st.floats(max_value=0.0) if open_low else st.floats(max_value=low, exclude_max=True)
    bad = data.draw(st.one_of(NOT_A_NUMBER, too_low, st.floats(min_value=high, exclude_min=True)))
    with pytest.raises(ValueError, match=name) as refused:
        klass(**{name: bad})
    assert f"{'(0' if open_low else f'[{low:g}'}, {high:g}]" in str(refused.value)  # the message gives the range
    good = data.draw(st.floats(min_value=0.0, max_value=high, exclude_min=True) if open_low else st.floats(min_value=low, max_value=high))
    if name == "control_period_s":  # a whole number of physics steps
        good = data.draw(st.integers(1, int(high * 240))) / 240
    assert getattr(klass(**{name: good}), name) == good


@pytest.mark.parametrize(("klass", "name", "low", "high"), INT_FIELDS, ids=_field_ids(INT_FIELDS))
@FUZZ
@given(data=st.data())
def test_int_fields_refuse_wrong_types_and_values_out_of_range(klass, name, low, high, data):
    bad = data.draw(st.one_of(NOT_AN_INT, st.integers(max_value=low - 1), st.integers(min_value=high + 1)))
    with pytest.raises(ValueError, match=rf"{name} must be an int in \[{low}, {high}\]"):
        klass(**{name: bad})
    good = data.draw(st.integers(min_value=low, max_value=high))
    value = getattr(klass(**{name: good}), name)
    assert value == good and type(value) is int


@pytest.mark.parametrize(
    ("klass", "name", "bad"),
    [
        (GridTouchConfig, "reward_type", "shaped"),
        (GridTouchConfig, "reward_type", b"dense"),
        (DebridementConfig, "fragment", "almond"),
        (DebridementConfig, "action_mode", None),
        (DebridementConfig, "remove_failed", 1),
        (DebridementConfig, "remove_failed", "yes"),
        (GridTouchConfig, "bias", "rusty"),
        (GridTouchConfig, "bias", 0.5),
        (GridTouchConfig, "camera_resolution", (640.0, 360.0)),
        (GridTouchConfig, "camera_resolution", (8, 8)),
        (GridTouchConfig, "camera_resolution", "640x360"),
        (GridTouchConfig, "camera_resolution", (640, 360, 3)),
        (WorldConfig, "gui", "no"),
        (WorldConfig, "camera_pose", np.eye(3)),
        (WorldConfig, "camera_pose", np.full((4, 4), np.nan)),
        (DebridementConfig, "timing", {"travel": {"max_speed_m_s": -1.0}}),
        (DebridementConfig, "gripper", {"jaw_friction": float("nan")}),
    ],
)
def test_choices_flags_sizes_and_nested_settings_are_checked(klass, name, bad):
    nested = {"timing": "MotionLimits.max_speed_m_s", "gripper": "GripperConfig.jaw_friction"}
    with pytest.raises(ValueError, match=nested.get(name, name)):
        klass(**{name: bad})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_picks": "8"}, r"max_picks must be an int in \[1, 64\], got '8' \(str\)"),
        ({"max_picks": True}, r"max_picks must be an int in \[1, 64\], got True \(bool\)"),
        ({"max_picks": 8.0}, r"max_picks must be an int"),
        ({"control_period_s": 1e9}, r"control_period_s must be a finite number in \(0, 10\] s, got 1000000000.0"),
        ({"gripper": {"jaw_friction": float("nan")}}, r"jaw_friction must be a finite number in \[0, 10\], got nan"),
    ],
)
def test_the_inputs_the_issue_found_accepted_are_refused_by_the_env(make_env, kwargs, message):
    with pytest.raises(ValueError, match=message):
        make_env("dvrk_gym/Debridement-v0", **kwargs)


# ---------------------------------------------------------------- actions
BOX = gym.spaces.Box(np.array([0.0, 0.0, -0.175, -np.pi / 2]), np.array([0.08, 0.085, -0.13, np.pi / 2]), dtype=np.float64)
NAMES = ("bx", "by", "bz", "yaw")


@FUZZ
@given(st.lists(st.complex_numbers(allow_nan=False, allow_infinity=False, max_magnitude=1.0), min_size=4, max_size=4))
def test_complex_actions_are_refused_even_with_a_zero_imaginary_part(values):
    with pytest.raises(ValueError, match="real numbers"):
        check_action(np.array(values, dtype=complex), BOX, NAMES)


@FUZZ
@given(st.lists(st.one_of(st.booleans(), st.text(max_size=3), st.none()), min_size=4, max_size=4))
def test_actions_of_bools_text_or_none_are_refused(values):
    with pytest.raises(ValueError, match="action"):
        check_action(values, BOX, NAMES)


@FUZZ
@given(st.integers(0, 3), st.sampled_from([float("nan"), float("inf"), -float("inf")]))
def test_a_non_finite_element_is_named(index, value):
    action = np.array([0.04, 0.04, -0.15, 0.0])
    action[index] = value
    with pytest.raises(ValueError, match=rf"action\[{index}\] \({NAMES[index]}\) is {value}"):
        check_action(action, BOX, NAMES)


@FUZZ
@given(st.lists(st.floats(-1.0, 1.0), min_size=0, max_size=7).filter(lambda v: len(v) != 4))
def test_a_wrong_shape_is_refused(values):
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        check_action(values, BOX, NAMES)


@FUZZ
@given(st.lists(st.floats(-10.0, 10.0), min_size=4, max_size=4), st.sampled_from([np.float32, np.float64, np.int64]))
def test_finite_real_actions_are_clipped_into_the_space(values, dtype):
    clipped, clamped = check_action(np.array(values).astype(dtype), BOX, NAMES)
    assert np.all(clipped >= BOX.low) and np.all(clipped <= BOX.high)
    assert np.array_equal(clamped, clipped != np.array(values).astype(dtype).astype(np.float64))


def test_an_env_refuses_a_complex_action_and_keeps_its_episode(make_env):
    env = make_env("dvrk_gym/GridTouch-v0", bias="none")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="real numbers"):
        env.step(np.array([0.04, 0.04, -0.15, 0.0]) + 1e-3j)
    _, _, terminated, _, info = env.step(np.array([0.04, 0.04, -0.15, 0.0]))  # the episode goes on
    assert terminated and "is_success" in info


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"circle": 35}, "circle"),
        ({"circle": -1}, "circle"),
        ({"circle": "3"}, "circle"),
        ({"circle": 3.0}, "circle"),
        ({"circle": True}, "circle"),
        ({"yaw": "0.5"}, "yaw"),
        ({"yaw": True}, "yaw"),
        ({"yaw": 2.0}, "yaw"),
        ({"yaw": float("nan")}, "yaw"),
        ({"yaw": 0.5j}, "yaw"),
        ({"yaw": 10**400}, "yaw.*too large for a float"),
        ({"speed": 1.0}, "unknown reset option"),
    ],
)
def test_grid_touch_reset_options_are_checked(make_env, options, message):
    env = make_env("dvrk_gym/GridTouch-v0", bias="none")
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("corner", [4, -1, True, "0", 1.0])
def test_exploration_corner_option_is_checked(make_env, corner):
    env = make_env("dvrk_gym/CalibrationExploration-v0")
    with pytest.raises(ValueError, match="corner"):
        env.reset(seed=0, options={"corner": corner})


# ---------------------------------------------------------------- copies
@pytest.mark.parametrize("env_id", ["dvrk_gym/CalibrationExploration-v0", "dvrk_gym/GridTouch-v0", "dvrk_gym/Debridement-v0"])
@pytest.mark.parametrize(("copier", "word"), [(copy.deepcopy, "deep-copied"), (pickle.dumps, "pickled"), (copy.copy, "copied")])
def test_envs_refuse_to_be_copied_or_pickled(make_env, env_id, copier, word):
    env = make_env(env_id, camera_resolution=(160, 90))
    target = env.unwrapped if copier is copy.copy else env  # a shallow copy of a wrapper shares its env by definition
    with pytest.raises(TypeError, match=f"cannot be {word}: it owns a PyBullet physics server"):
        copier(target)
    env.reset(seed=0)  # the env itself is untouched


def test_a_refused_first_reset_leaves_a_made_env_usable():
    """Gymnasium's passive checker (gym.make's default) breaks after a refused first reset: a
    mistyped option in a notebook left the env unusable, so the ids are registered without it."""
    assert gym.spec("dvrk_gym/GridTouch-v0").disable_env_checker
    env = gym.make("dvrk_gym/GridTouch-v0", camera_resolution=(320, 180))
    try:
        with pytest.raises(ValueError, match="unknown reset option"):
            env.reset(options={"yawn": 0.0})
        env.reset(seed=0)
        _, reward, terminated, _, _ = env.step(np.array([0.04, 0.04, -0.15, 0.0], dtype=np.float32))
        assert terminated and np.isfinite(reward)
    finally:
        env.close()


@pytest.mark.parametrize(
    "make",
    [
        lambda resolution: PipelineConfig(camera_resolution=resolution),
        lambda resolution: Profile(name="p", camera_resolution=resolution),
        lambda resolution: TrainConfig(camera_resolution=resolution),
        lambda resolution: GridTouchConfig(camera_resolution=resolution),
    ],
    ids=["pipeline", "profile", "training", "env"],
)
def test_configs_that_stamp_a_run_folder_refuse_another_aspect_before_it_is_made(make):
    """The aspect was checked only when the world was built, after the run had stamped its
    folder with it: the corrected command was then refused as a run with other settings."""
    with pytest.raises(ValueError, match=r"camera_resolution must keep the endoscope's 1920 x 1080 aspect.*got 100 x 100"):
        make((100, 100))
    make((320, 180))


def test_calibrate_refuses_another_aspect_without_making_its_folder(tmp_path, capsys):
    assert main(["calibrate", "--resolution", "16", "16", "--out", str(tmp_path / "run")]) == 2
    assert (
        "--resolution must keep the endoscope's 1920 x 1080 aspect (16:9, to a pixel), got 16 x 16; e.g. 320 x 180"
        in capsys.readouterr().err
    )
    assert not (tmp_path / "run").exists()


def test_a_run_refused_by_its_env_after_opening_its_folder_leaves_no_folder(tmp_path, capsys):
    """The env checks its camera when it is built, after the run has opened (and locked) its
    new folder: the refusal left the folder behind holding an empty ``run.lock``."""
    out = tmp_path / "new" / "run"
    assert main(["baseline", "train", "--algo", "sac_pick", "--resolution", "64", "36", "--out", str(out)]) == 2
    assert "camera_resolution 64 x 36 is too small for the endoscope to see the fragments" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("lock_text", "kept"), [("", False), ("4242", True)], ids=["released", "held"])
def test_a_made_folder_is_removed_with_its_released_lock_but_not_with_a_held_one(tmp_path, lock_text, kept):
    forget_created_folders()
    folder = writable_folder(tmp_path / "run")
    (folder / "run.lock").write_text(lock_text)
    remove_empty_created_folders()
    assert (folder / "run.lock").exists() is kept
    assert folder.exists() is kept


def test_a_made_folder_keeps_an_empty_lock_another_run_holds(tmp_path):
    """A run that has just taken the lock has not yet written its pid into it: a refused run
    that made the folder removed that empty lock, and a third run could then take the folder
    beside the first."""
    forget_created_folders()
    folder = writable_folder(tmp_path / "run")
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time, filelock; held = filelock.FileLock(sys.argv[1]); held.acquire(); print('holding', flush=True); "
            "time.sleep(600)",
            str(folder / "run.lock"),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "holding"
        assert (folder / "run.lock").read_text() == ""
        remove_empty_created_folders()
        assert (folder / "run.lock").exists() and folder.exists()
        with pytest.raises(RunFolderBusy, match="in use by another process"):
            RunFolder(folder)
    finally:
        holder.kill()
        holder.wait()


@pytest.mark.parametrize(
    ("argv", "usage", "said"),
    [
        (["reproduce", "--qiuck"], "usage: dvrk-gym reproduce [-h] [--quick]", "unrecognized arguments: --qiuck (did you mean --quick?)"),
        (
            ["baseline", "train", "--n-envz=2"],
            "usage: dvrk-gym baseline train",
            "unrecognized arguments: --n-envz=2 (did you mean --n-envs?)",
        ),
        (["demo", "--zzz"], "usage: dvrk-gym demo", "unrecognized arguments: --zzz\n"),
    ],
    ids=["typo", "subcommand", "nothing-near"],
)
def test_an_unknown_argument_is_refused_with_its_commands_usage_and_what_was_meant(argv, usage, said, capsys):
    """They were refused with the top level's usage (``dvrk-gym [-h] [-v] [--version] COMMAND``)
    and no suggestion."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(usage) and said in err


@pytest.mark.parametrize(
    ("argv", "verbose"), [(["demo"], False), (["-v", "demo"], True), (["demo", "-v"], True), (["baseline", "train", "--verbose"], True)]
)
def test_verbose_is_taken_before_or_after_the_command(argv, verbose):
    assert build_parser().parse_args(argv).verbose is verbose
