"""What an env does with calls it cannot honour: a refused reset changes nothing, a closed
env refuses every call, a carried state is checked before it is taken up, and a camera that
cannot see the whole printed grid is refused when the env is made."""

import dataclasses

import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError

from dvrk_gym.baselines.wrappers import TrainingYaws
from dvrk_gym.envs.debridement import DebridementEnv
from dvrk_gym.envs.exploration import CalibrationExplorationEnv
from dvrk_gym.envs.grid_touch import GridTouchEnv
from dvrk_gym.sim.robot.bias import BIAS_PRESETS

RESOLUTION = (320, 180)
ENV_CLASSES = (CalibrationExplorationEnv, GridTouchEnv, DebridementEnv)
TOUCH = np.array([0.04, 0.04, -0.15, 0.2], dtype=np.float32)


@pytest.fixture
def made():
    """Make envs (classes, not gym.make: no passive checker) closed after the test."""
    envs = []

    def _make(klass=GridTouchEnv, **kwargs):
        env = klass(camera_resolution=RESOLUTION, **kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[key], b[key]) for key in a)
    return np.array_equal(a, b)


def _touches(env, n: int) -> list:
    """``n`` episodes of one touch each: each reset's observation and info, and the step's reward."""
    out = []
    for _ in range(n):
        observation, info = env.reset()
        out.append((observation, info["circle_index"], info["target_yaw"], env.step(TOUCH)[1]))
    return out


@pytest.mark.parametrize(
    "options",
    [{"yaw": 0.5, "circle": 99}, {"relax": "yes", "yaw": 0.3}, {"yaw": 0.4, "circle": True}],
)
def test_a_refused_grid_touch_reset_changes_nothing(made, options):
    refused, twin = made(), made()
    for env in (refused, twin):
        env.reset(seed=3, options={"yaw": "random"})
        env.step(TOUCH)
    with pytest.raises(ValueError):
        refused.reset(options=options)
    with pytest.raises(ValueError, match="circle"):
        refused.reset(seed=7, options={"circle": 35})  # not reseeded, the tour not restarted
    expected, got = _touches(twin, 3), _touches(refused, 3)
    assert all(_same(a[0], b[0]) and a[1:] == b[1:] for a, b in zip(expected, got))


def test_a_refused_reset_mid_episode_leaves_the_episode_going(made):
    """The same steps, and the episode ends where it would have: a refused reset that zeroed the
    step count (not in the observation) would truncate the refused env later than its twin."""
    refused, twin = made(CalibrationExplorationEnv, max_steps=3), made(CalibrationExplorationEnv, max_steps=3)
    action = np.zeros(refused.action_space.shape, dtype=np.float32)
    for env in (refused, twin):
        env.reset(seed=0)
        env.step(action)
    with pytest.raises(ValueError, match="corner"):
        refused.reset(seed=1, options={"corner": 9})
    for _ in range(2):
        got, expected = refused.step(action), twin.step(action)
        assert _same(got[0], expected[0]) and got[2:4] == expected[2:4]
    assert got[3], "the third step of the episode truncates it"


@pytest.mark.parametrize(
    ("seed", "options", "error", "message"),
    [
        ("3", None, TypeError, "seed must be None or an int"),
        (3.0, None, TypeError, "seed must be None or an int"),
        (True, None, TypeError, "seed must be None or an int"),
        (-1, None, ValueError, "non-negative"),
        (None, "relax", TypeError, "options must be None or a dict"),
        (None, [("relax", True)], TypeError, "options must be None or a dict"),
        (None, {3: 1}, ValueError, "unknown reset option"),
    ],
)
def test_bad_seeds_and_options_are_refused_clearly(made, seed, options, error, message):
    env = made()
    with pytest.raises(error, match=message):
        env.reset(seed=seed, options=options)
    env.reset(seed=0)  # usable


def test_a_numpy_int_seed_is_the_same_seed(made):
    a, b = made(), made()
    assert _same(a.reset(seed=np.int64(3))[0], b.reset(seed=3)[0])


@pytest.mark.parametrize("klass", ENV_CLASSES)
def test_a_closed_env_refuses_every_call_but_close(made, klass):
    env = made(klass)
    env.reset(seed=0)
    env.close()
    for call in (lambda: env.step(env.action_space.sample()), lambda: env.reset(seed=0), env.render):
        with pytest.raises(ClosedEnvironmentError, match="the env is closed"):
            call()
    env.close()  # twice is fine


@pytest.mark.parametrize(
    ("attribute", "value", "message"),
    [
        ("_yaw_setting", 7.0, "_yaw_setting"),
        ("_yaw_setting", None, "_yaw_setting"),
        ("_next_circle", 99, "_next_circle"),
        ("_next_circle", 1.0, "_next_circle"),
        ("_touched", "yes", "_touched"),
    ],
)
def test_a_carried_state_with_attributes_grid_touch_cannot_carry_is_refused(made, attribute, value, message):
    env = made()
    env.reset(seed=0)
    env.step(TOUCH)
    state = env.carried_state()
    before = env.carried_state()
    state["attributes"][attribute] = value
    with pytest.raises(ValueError, match=message):
        env.restore_carried_state(state)
    assert env.carried_state() == before  # nothing taken up


@pytest.mark.parametrize("episodes", [-1, 2.0, "3", True])
def test_the_training_yaw_wrapper_refuses_an_episode_count_it_cannot_carry(made, episodes):
    wrapper = TrainingYaws(made())
    with pytest.raises(ValueError, match="_episodes"):
        wrapper._check_carried_attributes({"_episodes": episodes})
    wrapper._check_carried_attributes({"_episodes": 70})


def test_a_resolution_that_loses_a_printed_circle_is_refused_when_grid_touch_is_made():
    with pytest.raises(ValueError, match=r"128 x 72 px the endoscope does not find printed circle\(s\) \[2, 5, 14, 15, 30\]"):
        GridTouchEnv(camera_resolution=(128, 72))


@pytest.mark.parametrize("resolution", [(160, 96), (640, 480), (1920, 1440), (1280, 1080)])
def test_a_camera_of_another_aspect_than_the_endoscopes_is_refused(resolution):
    """The detector's noise, search boxes and whole pixels scale with the width: at 640 x 480 a
    marker inside the authors' left search box was dropped, one outside the right one kept."""
    with pytest.raises(ValueError, match="must keep the endoscope's 1920 x 1080 aspect"):
        GridTouchEnv(camera_resolution=resolution)


@pytest.mark.parametrize("klass", ENV_CLASSES)
def test_an_env_rebuilds_from_its_config_as_a_dict_bias_included(made, klass):
    bias = dataclasses.replace(BIAS_PRESETS["paper"], wrist_settle_lag=0.0)
    env = made(klass, bias=bias)
    again = made(klass, **{k: v for k, v in dataclasses.asdict(env.config).items() if k != "camera_resolution"})
    assert again.config == env.config and again.config.bias == bias
    with pytest.raises(ValueError, match="bias given as a dict must hold BiasConfig's fields"):
        klass(bias={"stretch": 1.0})


@pytest.mark.parametrize(
    ("action", "message"),
    [([[0.0, 0.0], [0.0]], "action must be an array of shape"), (np.ones(50, bool), r"action must have shape \(4,\)")],
)
def test_ragged_or_long_actions_are_refused_in_one_short_line(made, action, message):
    env = made()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message) as refused:
        env.step(action)
    assert "\n" not in str(refused.value) and len(str(refused.value)) < 240


def test_a_refused_reset_through_the_training_yaws_keeps_their_schedule(made):
    refused, twin = TrainingYaws(made()), TrainingYaws(made())
    for env in (refused, twin):
        env.reset(seed=0)
    with pytest.raises(ValueError, match="circle"):
        refused.reset(options={"circle": 99})
    assert refused._episodes == twin._episodes == 1


@pytest.mark.parametrize("klass", ENV_CLASSES)
def test_an_env_dropped_without_close_frees_its_physics_server_at_once(klass):
    """No reference cycle keeps a dropped env's server: a loop of envs made and dropped
    (a hyper-parameter search) would hold one server, and its memory, per env until the
    garbage collector ran."""
    import gc

    import pybullet

    env = klass(camera_resolution=RESOLUTION)
    env.reset(seed=0)
    server = env.world.physics.client._client
    assert pybullet.getConnectionInfo(server)["isConnected"]
    gc.disable()
    try:
        del env
        assert not pybullet.getConnectionInfo(server)["isConnected"]
    finally:
        gc.enable()


def test_a_closed_debridement_keeps_its_buffered_frames_to_itself(made):
    env = made(DebridementEnv, render_mode="rgb_array_list")
    env.reset(seed=0)  # buffers the first frame
    env.close()
    with pytest.raises(ClosedEnvironmentError, match="the env is closed"):
        env.render()


def test_a_closed_env_refuses_its_carried_state_calls_too(made):
    env = made()
    env.reset(seed=0)
    state = env.carried_state()
    env.close()
    with pytest.raises(ClosedEnvironmentError):
        env.carried_state()
    with pytest.raises(ClosedEnvironmentError):
        env.restore_carried_state(state)


def test_a_refused_reset_leaves_the_resume_record_and_numpy_seeds_are_recorded_as_ints(made):
    from dvrk_gym.baselines.resume.reset_records import ResetRecorder

    env = ResetRecorder(TrainingYaws(made()))
    env.reset(seed=np.int64(1))
    recorded = env.last_reset()
    assert recorded["seed"] == 1 and type(recorded["seed"]) is int
    with pytest.raises(ValueError, match="circle"):
        env.reset(options={"circle": 99})
    assert env.last_reset() == recorded and env.between_episodes()
