"""Debridement-v0: what it shows and accepts: perception, delta mode, the Gymnasium API,
strict inputs, the command line (the scene, picks and determinism: test_env_debridement.py)."""

import json
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from conftest import SMALL
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from test_env_debridement import ENV_ID, _first_on_paper, debridement_maker, oracle_action

from dvrk_gym.envs.debridement import fragment_target, image_angle_to_yaw
from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.sim.endoscope.fragment_detection import MIN_FRAGMENT_IMAGE_WIDTH_PX, detect_fragments
from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.table.contact import CONTACTS
from dvrk_gym.sim.world import DvrkWorld


@pytest.fixture
def make(make_env):
    """Debridement envs at the small test resolution; bias "none" unless asked."""
    return debridement_maker(make_env)


# ---------------------------------------------------------------------------- perception
def test_detections_triangulate_to_the_true_centres_and_give_the_yaw(make):
    env = make(camera_resolution=(960, 540))
    obs, _ = env.reset(seed=3)
    world, table = env.unwrapped.world, env.unwrapped.table
    assert obs["fragment_seen"].sum() == 8
    truth = world.camera.depth_scale * world.camera.to_camera_frame(table.true_fragment_positions())  # as the authors triangulate
    yaws = np.array([f.yaw() for f in table.fragments])
    for position, angle in zip(obs["fragment_positions"], obs["fragment_angles"]):
        distances = np.linalg.norm(truth - position, axis=1)
        i = int(np.argmin(distances))
        assert distances[i] < 7e-4
        error = (image_angle_to_yaw(float(angle)) - yaws[i] + math.pi / 2) % math.pi - math.pi / 2
        assert abs(error) < math.radians(6.0)
    u = np.array([world.camera.project(world.camera.to_world(p / world.camera.depth_scale))[0][0, 0] for p in obs["fragment_positions"]])
    assert np.all(np.diff(u) < 0)  # the receptacle's side of the image first


def test_two_pass_detection_equals_a_full_frame_detection(make):
    env = make(camera_resolution=SMALL)
    env.reset(seed=9)
    u = env.unwrapped
    client = u.world.physics.client
    detections = u.observer.observe(client)
    full = [b for b in detect_fragments(u.world.render("left"), u.observer.min_area_px) if u.observer.on_paper(b.centroid)]
    assert len(detections) == len(full) == 8
    for d in detections:
        nearest = min(full, key=lambda b: np.linalg.norm(b.centroid - d.left.centroid))
        np.testing.assert_allclose(d.left.centroid, nearest.centroid, atol=0.02)
        assert d.left.area_px == pytest.approx(nearest.area_px, abs=2)
        assert d.image_angle_rad == pytest.approx(nearest.angle_rad, abs=0.01)


@pytest.mark.parametrize("width", [96, 128, 192])
def test_small_endoscope_images_still_see_every_fragment(make, width):
    """The coarse pass keeps MIN_FRAGMENT_IMAGE_WIDTH_PX: at a quarter of 128 px it saw 0-2 fragments of 8."""
    env = make(camera_resolution=(width, round(width * 9 / 16)), fragment="raisin")
    assert env.unwrapped.observer.scale == min(4, width // MIN_FRAGMENT_IMAGE_WIDTH_PX)
    assert [int(env.reset(seed=seed)[0]["fragment_seen"].sum()) for seed in range(3)] == [8, 8, 8]


def test_an_endoscope_too_small_to_see_the_fragments_is_refused_before_the_world_is_built(make, monkeypatch):
    built = []
    monkeypatch.setattr(DvrkWorld, "__init__", lambda *args, **kwargs: built.append(args))
    with pytest.raises(ValueError, match=r"camera_resolution 64 x 36 is too small .* at least 80 px wide"):
        make(camera_resolution=(64, 36))
    assert not built


def test_fragment_target_is_the_first_fragment_seen_or_the_middle_of_the_view():
    observation = {
        "fragment_positions": np.array([[0.01, 0.02, 0.19], [0.03, 0.0, 0.2]] + [[0.0, 0.0, 0.0]] * 6),
        "fragment_angles": np.array([0.3, -0.2] + [0.0] * 6),
        "fragment_seen": np.array([0, 1, 0, 0, 0, 0, 0, 0]),
    }
    position, yaw = fragment_target(observation)
    np.testing.assert_allclose(position, [0.03, 0.0, 0.2])
    assert yaw == pytest.approx(image_angle_to_yaw(-0.2)) and -math.pi / 2 <= yaw < math.pi / 2
    observation["fragment_seen"][:] = 0
    position, yaw = fragment_target(observation)
    np.testing.assert_allclose(position, [0.0, 0.0, 0.19])


# ---------------------------------------------------------------------------- delta mode
def test_delta_mode_moves_by_the_increment_at_10_hz_and_truncates(make):
    env = make(action_mode="delta", max_steps=3)
    obs, _ = env.reset(seed=0)
    start, clock = obs["reported_pose"][:3].copy(), env.unwrapped.world.clock.time_s
    obs, reward, terminated, truncated, info = env.step(np.array([0.004, 0.0, 0.002, 0.1], dtype=np.float32))
    np.testing.assert_allclose(obs["reported_pose"][:3] - start, [0.004, 0.0, 0.002], atol=1e-6)
    assert env.unwrapped.world.clock.time_s - clock == pytest.approx(0.1)
    assert reward == 0.0 and not terminated and not truncated and info["sim_error"] is None
    env.step(np.zeros(4, dtype=np.float32))
    *_, terminated, truncated, _ = env.step(np.zeros(4, dtype=np.float32))
    assert truncated and not terminated


def test_delta_mode_videos_play_at_the_control_rate(make):
    """RecordVideo reads render_fps: delta mode renders a frame per control step, and its videos played at 4 fps."""
    assert make(action_mode="delta", control_period_s=0.05).metadata["render_fps"] == pytest.approx(20.0)
    assert make().metadata["render_fps"] == type(make().unwrapped).metadata["render_fps"] == 4


# ---------------------------------------------------------------------------- API and inputs
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["primitive", "delta"])
def test_passes_gymnasium_and_sb3_checkers(make, mode):
    env = make(action_mode=mode)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # both checkers advise a [-1, 1] action box; ours is SI
        check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(env.unwrapped)


def test_non_finite_action_names_the_element_and_leaves_the_world_intact(make):
    env = make().unwrapped
    env.reset(seed=0)
    action = env.action_space.sample()
    action[2] = np.nan
    with pytest.raises(ValueError, match=r"action\[2\] \(bz\)"):
        env.step(action)
    delta = make(action_mode="delta").unwrapped
    delta.reset(seed=0)
    with pytest.raises(ValueError, match=r"action\[3\] \(djaw\)"):
        delta.step(np.array([0.0, 0.0, 0.0, np.inf]))
    obs, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)


def test_step_before_reset_and_unknown_options_are_clear_errors(make):
    env = make().unwrapped
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(env.action_space.sample())
    with pytest.raises(ValueError, match="unknown reset option.*valid options"):
        env.reset(seed=0, options={"colour": "red"})
    with pytest.raises(TypeError, match="unexpected keyword argument 'fragments'"):
        gym.make(ENV_ID, fragments="raisin")
    with pytest.raises(ValueError, match="pumpkin_seed"):
        gym.make(ENV_ID, fragment="almond")
    with pytest.raises(ValueError, match="primitive"):
        gym.make(ENV_ID, action_mode="torque")
    with pytest.raises(ValueError, match=r"contact must be one of \['compliant', 'rigid'\]"):
        gym.make(ENV_ID, contact="soft")


def test_out_of_range_pick_is_clamped_and_reported(make):
    env = make().unwrapped
    env.reset(seed=0)
    action = oracle_action(_first_on_paper(env))
    action[0] = 5.0
    obs, _, _, _, info = env.step(action)
    assert "bx" in info["clamped"] and env.observation_space.contains(obs)


def test_physics_blow_up_ends_the_episode_with_sim_error_not_a_crash(make):
    env = make().unwrapped
    env.reset(seed=0)
    flown = env.table.fragments[3]
    env.world.physics.client.resetBasePositionAndOrientation(flown.body_id, [2.0, 0.0, 0.5], [0, 0, 0, 1])
    obs, reward, terminated, truncated, info = env.step(oracle_action(_first_on_paper(env)))
    assert terminated and "left the scene" in info["sim_error"]
    assert env.observation_space.contains(obs)
    assert all(np.isfinite(v).all() for v in obs.values())
    with pytest.raises(ResetNeeded):
        env.step(env.action_space.sample())


# ---------------------------------------------------------------------------- the command line
@pytest.mark.slow
def test_debride_command_writes_the_trial_table(tmp_path, capsys):
    """A rigid-body calibrator fitted on exact data of the unbiased robot: the command runs,
    prints the table and writes JSON, text and the outcome grid."""
    import argparse

    from dvrk_gym.calibration.models.rigid import RigidBodyCalibrator
    from dvrk_gym.cli.debridement import add_commands
    from dvrk_gym.sim.endoscope.baseline import PAPER_BASELINE_M, TRUE_BASELINE_M
    from dvrk_gym.sim.endoscope.camera import StereoCamera

    rng = np.random.default_rng(0)
    camera = StereoCamera()
    rows, targets = [], []
    for yaw in kin.PAPER_YAWS_RAD:
        pitch, roll = kin.paper_pitch_roll(yaw)
        tips = WORKSPACE_CENTER_M + rng.uniform([-0.03, -0.03, 0.0], [0.03, 0.03, 0.004], (40, 3))
        reference = tool_pose(WORKSPACE_CENTER_M + [0.0, 0.0, 0.01], yaw)
        offset = kin.touch_point(ik.inverse_kinematics(reference)) - reference[:3, 3]
        for tip in tips:
            # As the world's endoscope triangulates what is not the tape: scaled by the authors'
            # baseline over the true one.
            rows.append([*camera.to_camera_frame(tip)[0] * PAPER_BASELINE_M / TRUE_BASELINE_M, yaw, pitch, roll])
            targets.append(tip - offset)
    RigidBodyCalibrator().fit(np.array(rows), np.array(targets)).save(tmp_path / "rbt.zip")
    from dvrk_gym.utils.run_folder import SOURCE_KEY
    from dvrk_gym.utils.source_fingerprint import source_fingerprint

    stamp = {"bias": "none", "bias_seed": 0, SOURCE_KEY: source_fingerprint().to_json()}  # made by this dvrk_gym
    (tmp_path / "pipeline_config.json").write_text(json.dumps(stamp))
    parser = argparse.ArgumentParser()
    add_commands(parser.add_subparsers(dest="command"))
    args = parser.parse_args(
        [
            "debride",
            "--calibrator",
            "rbt",
            "--fragment",
            "raisin",
            "--trials",
            "1",
            "--calibration",
            str(tmp_path),
            "--out",
            str(tmp_path / "out"),
            "--resolution",
            "640",
            "360",
            "--no-progress",
            "--contact",
            "rigid",
        ]
    )
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    assert "total  success" in printed and "paper" in printed
    written = json.loads((tmp_path / "out" / "debridement_rbt_raisin_rigid.json").read_text())
    assert written["contact"] == "rigid"  # the paper the picks met is recorded, and named: a compliant run does not overwrite it
    choices = next(a.choices for a in parser._subparsers._group_actions[0].choices["debride"]._actions if a.dest == "contact")
    assert set(choices) == set(CONTACTS)
    # One outcome per pick: eight, or fewer when no raisin is left on the paper sooner (a pick can carry two).
    assert 7 <= len(written["trials"][0]["outcomes"].split(",")) <= 8
    assert written["totals"]["success"] >= 6
    assert (tmp_path / "out" / "debridement_rbt_raisin_rigid.png").stat().st_size > 1000


def test_nested_settings_can_be_given_as_dicts_and_bad_ones_are_refused():
    import dataclasses

    from dvrk_gym.envs.debridement_config import DebridementConfig
    from dvrk_gym.envs.picks import PickTiming
    from dvrk_gym.sim.robot.motion import MotionLimits
    from dvrk_gym.sim.table.grasp import GripperConfig

    timing = PickTiming(travel=MotionLimits(max_speed_m_s=0.1), grip_dwell_s=0.5)
    gripper = GripperConfig(jaw_friction=1.2)
    from_dicts = DebridementConfig(timing=dataclasses.asdict(timing), gripper=dataclasses.asdict(gripper))  # as JSON gives them
    assert from_dicts.timing == timing and from_dicts.gripper == gripper
    with pytest.raises(ValueError, match="grip_dwell"):
        DebridementConfig(timing={"grip_dwell": 1.0})  # a misspelt field
    with pytest.raises(ValueError, match="timing must be a PickTiming"):
        DebridementConfig(timing=0.5)


def test_partial_gripper_and_timing_dicts_change_only_their_fields_of_the_envs_defaults():
    from dvrk_gym.envs.debridement_config import DEFAULT_PICK_TIMING, SERRATED_GRIPPER, DebridementConfig

    config = DebridementConfig(gripper={"grip_force_n": 1.0}, timing={"travel": {"max_speed_m_s": 0.065}, "grip_dwell_s": 1.4})
    assert config.gripper.jaw_friction == SERRATED_GRIPPER.jaw_friction  # was the class default, 1.0 against 1.5
    assert config.timing.travel == DEFAULT_PICK_TIMING.travel  # its acceleration was the class default's
    assert config.timing.grip_dwell_s == 1.4 and config.timing.descend == DEFAULT_PICK_TIMING.descend


@pytest.mark.parametrize("period", [0.01, 0.03, 0.1001, 1e-9])
def test_a_control_period_of_no_whole_number_of_physics_steps_is_refused(period):
    from dvrk_gym.envs.debridement_config import PHYSICS_STEP_S, DebridementConfig
    from dvrk_gym.sim.physics.client import DEFAULT_TIME_STEP_S

    assert PHYSICS_STEP_S == DEFAULT_TIME_STEP_S
    with pytest.raises(ValueError, match="not a whole number of physics steps"):  # 0.01 s lasted 0.0125
        DebridementConfig(control_period_s=period)
    assert DebridementConfig(control_period_s=0.05).control_period_s == 0.05
