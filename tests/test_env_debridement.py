"""Debridement-v0: the scene, perception, picks judged from the truth, determinism, strict inputs."""

import json
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from conftest import SMALL, json_from_fresh_process
from dvrk_gym.envs.debridement import PAPER_PHASE_S, PHASES, fragment_target, image_angle_to_yaw
from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.sim.table import judge
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.endoscope.fragment_detection import detect_fragments
from dvrk_gym.sim.table.fragments import FRAGMENT_TYPES, MIN_GAP_M, TRUNCATE_SD, outline_gap
from dvrk_gym.sim.table.grasp import GRASP_TIP_CLEARANCE_M
from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M

ENV_ID = "dvrk_gym/Debridement-v0"
SURFACE_Z_M = float(WORKSPACE_CENTER_M[2])


@pytest.fixture
def make(make_env):
    """Debridement envs at the small test resolution; bias "none" unless asked."""

    def _make(**kwargs):
        kwargs.setdefault("bias", "none")
        return make_env(ENV_ID, **kwargs)

    return _make


def _first_on_paper(env):
    u = env.unwrapped
    return u.world.fragments[u._on_paper()[0]]


def oracle_action(fragment, along_m: float = 0.0, across_m: float = 0.0) -> np.ndarray:
    """The pick a perfect calibration would command (bias "none" only): the closed jaw tip
    on the fragment's true centre, moved along / across its length, its yaw (tests only)."""
    yaw = (fragment.yaw() + math.pi / 2) % math.pi - math.pi / 2
    pose = fragment.pose()
    along = pose[:3, 0].copy()
    along[2] = 0.0
    along /= np.linalg.norm(along)
    across = np.array([-along[1], along[0], 0.0])
    tip = fragment.position() + along_m * along + across_m * across
    reference = tool_pose(WORKSPACE_CENTER_M + [0.0, 0.0, 0.01], yaw)
    q = kin.inverse_kinematics(reference)
    command = tip - (kin.touch_point(q) - reference[:3, 3])
    return np.array([*command, yaw], dtype=np.float32)


# ---------------------------------------------------------------------------- the scene
@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_scene_has_eight_fragments_of_the_papers_sizes_3_mm_apart_on_the_paper(make, kind):
    env = make(fragment=kind)
    env.reset(seed=4)
    fragments = env.unwrapped.world.fragments
    assert len(fragments) == 8 and all(f.kind.name == kind for f in fragments)
    spec = FRAGMENT_TYPES[kind]
    sizes = np.array([f.size_m for f in fragments])
    assert np.all(np.abs(sizes - spec.size_mean_m) <= TRUNCATE_SD * np.array(spec.size_sd_m) + 1e-12)
    assert all(f.on_paper() for f in fragments)
    for i in range(8):
        for j in range(i):
            a, b = fragments[i], fragments[j]
            gap = outline_gap(a.size_m, a.position()[:2], a.yaw(), b.size_m, b.position()[:2], b.yaw())
            assert gap >= MIN_GAP_M - 1e-4, (i, j, gap)  # settling moves them by microns at most
    yaws = np.array([f.yaw() for f in fragments])
    assert np.ptp(yaws) > 1.0  # any orientation


def test_reset_is_bit_identical_for_a_seed_whatever_came_before(make):
    env = make()
    def state():
        world = env.unwrapped.world
        return [np.concatenate([f.position(), f.orientation()]) for f in world.fragments], world.q_true.copy()
    obs_a, _ = env.reset(seed=5)
    first = state()
    env.reset(seed=6)
    env.step(env.action_space.sample())
    obs_b, _ = env.reset(seed=5)
    second = state()
    for x, y in zip(first[0] + [first[1]], second[0] + [second[1]]):
        assert np.array_equal(x, y)
    for key in obs_a:
        assert np.array_equal(obs_a[key], obs_b[key])


def test_jaws_squeeze_a_raisin_more_than_a_seed_in_the_envs_world(make):
    squeezed = {}
    for kind in ("pumpkin_seed", "raisin"):
        env = make(fragment=kind)
        env.reset(seed=1)
        world = env.unwrapped.world
        fragment = _first_on_paper(env)
        action = oracle_action(fragment)
        world.move_to(tool_pose(action[:3] + [0, 0, 0.01], float(action[3])), kin.JAW_FULLY_OPEN_RAD)
        world.move_stepped(tool_pose(action[:3] - [0, 0, 0.002], float(action[3])), min_tip_clearance_m=GRASP_TIP_CLEARANCE_M)
        assert fragment.compression() == 0.0
        world.actuate_jaws(-0.3)
        assert world.gripper.held() == {fragment.name: "grasp"}
        squeezed[kind] = fragment.compression()
        # the jaws stopped on it: open by its width less the squeeze, not closed
        assert world.jaw_angle > 0.3
        world.actuate_jaws(kin.JAW_FULLY_OPEN_RAD, 1.0)
        assert not world.gripper.held() and fragment.compression() < 0.1 * squeezed[kind]
    assert squeezed["pumpkin_seed"] > 5e-5
    assert squeezed["raisin"] > 3 * squeezed["pumpkin_seed"]


# ---------------------------------------------------------------------------- picks and the judge
@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_perfectly_calibrated_pick_delivers_the_fragment(make, kind):
    env = make(fragment=kind)
    env.reset(seed=0)
    fragment = _first_on_paper(env)
    _, reward, terminated, _, info = env.step(oracle_action(fragment))
    assert info["outcome"] == "-" and reward == 1.0 and not terminated
    assert info["outcomes"] == "-" and info["successes"] == 1 and info["picks"] == 1
    assert list(info["phase_times_s"]) == list(PHASES)
    assert info["time_per_fragment"] == pytest.approx(sum(info["phase_times_s"].values())) == pytest.approx(info["sim_time_s"])
    assert info["phase_times_s"]["grip"] == pytest.approx(PAPER_PHASE_S["grip"], abs=0.01)  # a dwell
    assert judge.in_receptacle(fragment.position())
    assert info["true_grip_offset_ratio"] < 0.05
    assert info["true_tip_at_grip"][2] >= SURFACE_Z_M + GRASP_TIP_CLEARANCE_M - 3e-4  # the jaws did not dig in
    assert info["fragments_on_paper"] == 7


def test_pick_5_mm_off_along_a_seed_is_judged_a_calibration_miss(make):
    env = make(fragment="pumpkin_seed")
    env.reset(seed=0)
    fragment = _first_on_paper(env)
    _, reward, _, _, info = env.step(oracle_action(fragment, along_m=0.005))
    assert info["outcome"] == "A" and reward == 0.0
    assert info["true_grip_offset_ratio"] > judge.WELL_PLACED_RATIO
    assert not judge.in_receptacle(fragment.position())
    assert info["fragments_on_paper"] == 7  # the failed one is taken away (one attempt each)


def test_raisin_pierced_by_one_jaw_tip_is_judged_c_and_taken_off_the_jaw(make):
    env = make(fragment="raisin")
    env.reset(seed=0)
    fragment = _first_on_paper(env)
    # the jaws land 6.5 mm across, so one open tip comes down on the raisin's top
    _, reward, _, _, info = env.step(oracle_action(fragment, across_m=0.0065))
    assert info["outcome"] == "C" and reward == 0.0
    assert env.unwrapped.world.gripper.held() == {}
    assert not judge.in_receptacle(fragment.position()) and not fragment.on_paper()


@pytest.mark.slow
def test_oracle_episode_reports_outcomes_and_paper_like_times(make):
    env = make(fragment="raisin")
    env.reset(seed=2)
    done, rewards = False, 0.0
    while not done:
        _, reward, terminated, truncated, info = env.step(oracle_action(_first_on_paper(env)))
        rewards += reward
        done = terminated or truncated
    outcomes = info["outcomes"].split(",")
    assert len(outcomes) == 8 and set(outcomes) <= set(judge.OUTCOMES)
    assert info["successes"] == outcomes.count("-") == rewards >= 7
    assert info["n_A"] + info["n_B"] + info["n_C"] == 8 - info["successes"]
    assert info["time_per_fragment"] == pytest.approx(sum(info[f"time_{p}_s"] for p in PHASES))
    assert info["time_per_fragment"] == pytest.approx(sum(PAPER_PHASE_S.values()), rel=0.15)
    for phase in PHASES:
        assert info[f"time_{phase}_s"] == pytest.approx(PAPER_PHASE_S[phase], rel=0.25), phase
    assert info["sim_time_s"] == pytest.approx(8 * info["time_per_fragment"])
    assert info["sim_error"] is None and info["fragments_on_paper"] == 0


def _rollout(env, seed: int) -> tuple[list[float], list]:
    """Reset with ``seed`` and pick with the yaw of the fragment seen first: every observation
    value, and the outcome, clock and grip offset."""
    observations, outcomes = [env.reset(seed=seed)[0]], []
    obs, _, _, _, info = env.step(fragment_target_action(observations[-1]))
    observations.append(obs)
    outcomes.append((info["outcomes"], info["sim_time_s"], info["true_grip_offset_ratio"], info["true_tip_at_grip"].tolist()))
    return [float(v) for o in observations for key in sorted(o) for v in np.ravel(o[key])], outcomes


def fragment_target_action(observation) -> np.ndarray:
    """An uncalibrated pick with the yaw of the fragment seen first."""
    _, yaw = fragment_target(observation)
    return np.array([0.04, 0.04, -0.155, float(kin.nearest_paper_yaw(yaw))], dtype=np.float32)


def test_same_seed_and_actions_give_identical_observations_and_outcomes(make):
    env = make(fragment="pumpkin_seed", bias="paper")
    first = _rollout(env, 7)
    _rollout(env, 8)
    assert _rollout(env, 7) == first


@pytest.mark.slow
def test_observations_and_outcomes_are_identical_across_processes(make):
    here = _rollout(make(fragment="raisin", bias="paper"), 3)
    code = (
        "import json, gymnasium as gym, dvrk_gym, test_env_debridement as t\n"
        f"env = gym.make({ENV_ID!r}, fragment='raisin', bias='paper', camera_resolution={SMALL!r})\n"
        "print(json.dumps(t._rollout(env, 3)))\n"
    )
    there = json_from_fresh_process(code)
    assert json.loads(json.dumps(here)) == there


def test_judge_rules():
    assert judge.judge(delivered=True, pierced=True, ratio=3.0) == "-"
    assert judge.judge(delivered=False, pierced=True, ratio=0.1) == "C"
    assert judge.judge(delivered=False, pierced=False, ratio=0.8) == "A"
    assert judge.judge(delivered=False, pierced=False, ratio=judge.WELL_PLACED_RATIO) == "B"
    assert judge.judge(delivered=False, pierced=False, ratio=math.inf) == "A"
    assert judge.judge(delivered=False, pierced=False, ratio=0.1, above_top_m=0.002) == "A"  # closed over it
    assert judge.outcome_row(["-", "A", "-", "B"]) == "-,A,-,B"
    assert judge.outcome_counts(["-", "A", "-", "C"]) == {"success": 2, "A": 1, "B": 0, "C": 1}
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # length along base y
    offset = judge.fragment_offset([0.001, 0.003, 0.0], pose)
    np.testing.assert_allclose(offset, [0.003, -0.001])
    assert judge.offset_ratio([0.006, 0.0], [0.012, 0.006, 0.002]) == pytest.approx(1.0)
    assert judge.physics_failure(np.zeros((2, 3)) + [0.04, 0.04, -0.16]) is None
    assert "left the scene" in judge.physics_failure(np.array([[0.04, 0.04, -0.16], [3.0, 0.0, 0.0]]))
    assert "finite" in judge.physics_failure(np.array([[np.nan, 0.0, 0.0]]))


# ---------------------------------------------------------------------------- perception
def test_detections_triangulate_to_the_true_centres_and_give_the_yaw(make):
    env = make(camera_resolution=(960, 540))
    obs, _ = env.reset(seed=3)
    world = env.unwrapped.world
    assert obs["fragment_seen"].sum() == 8
    truth = world.camera.to_camera_frame(world.true_fragment_positions())
    yaws = np.array([f.yaw() for f in world.fragments])
    for position, angle in zip(obs["fragment_positions"], obs["fragment_angles"]):
        distances = np.linalg.norm(truth - position, axis=1)
        i = int(np.argmin(distances))
        assert distances[i] < 7e-4
        error = (image_angle_to_yaw(float(angle)) - yaws[i] + math.pi / 2) % math.pi - math.pi / 2
        assert abs(error) < math.radians(6.0)
    u = np.array([world.camera.project(world.camera.to_world(p))[0][0, 0] for p in obs["fragment_positions"]])
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
    with pytest.raises(ValueError, match="unknown argument.*fragments"):
        gym.make(ENV_ID, fragments="raisin")
    with pytest.raises(ValueError, match="pumpkin_seed"):
        gym.make(ENV_ID, fragment="almond")
    with pytest.raises(ValueError, match="primitive"):
        gym.make(ENV_ID, action_mode="torque")


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
    flown = env.world.fragments[3]
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
    from dvrk_gym.sim.endoscope.camera import StereoCamera

    rng = np.random.default_rng(0)
    camera = StereoCamera()
    rows, targets = [], []
    for yaw in kin.PAPER_YAWS_RAD:
        pitch, roll = kin.paper_pitch_roll(yaw)
        tips = WORKSPACE_CENTER_M + rng.uniform([-0.03, -0.03, 0.0], [0.03, 0.03, 0.004], (40, 3))
        reference = tool_pose(WORKSPACE_CENTER_M + [0.0, 0.0, 0.01], yaw)
        offset = kin.touch_point(kin.inverse_kinematics(reference)) - reference[:3, 3]
        for tip in tips:
            rows.append([*camera.to_camera_frame(tip)[0], yaw, pitch, roll])
            targets.append(tip - offset)
    RigidBodyCalibrator().fit(np.array(rows), np.array(targets)).save(tmp_path / "rbt.npz")
    (tmp_path / "pipeline_config.json").write_text(json.dumps({"bias": "none", "bias_seed": 0}))
    parser = argparse.ArgumentParser()
    add_commands(parser.add_subparsers(dest="command"))
    args = parser.parse_args([
        "debride", "--calibrator", "rbt", "--fragment", "raisin", "--trials", "1", "--calibration", str(tmp_path),
        "--out", str(tmp_path / "out"), "--resolution", "640", "360", "--no-progress",
    ])
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    assert "total  success" in printed and "paper" in printed
    written = json.loads((tmp_path / "out" / "debridement_rbt_raisin.json").read_text())
    assert len(written["trials"][0]["outcomes"].split(",")) == 8
    assert written["totals"]["success"] >= 6
    assert (tmp_path / "out" / "debridement_rbt_raisin.png").stat().st_size > 1000


def test_nested_settings_can_be_given_as_dicts_and_bad_ones_are_refused():
    import dataclasses

    from dvrk_gym.envs.debridement import DebridementConfig, PickTiming
    from dvrk_gym.sim.table.grasp import GripperConfig
    from dvrk_gym.sim.robot.motion import MotionLimits

    timing = PickTiming(travel=MotionLimits(max_speed_m_s=0.1), grip_dwell_s=0.5)
    gripper = GripperConfig(jaw_friction=1.2)
    from_dicts = DebridementConfig(timing=dataclasses.asdict(timing), gripper=dataclasses.asdict(gripper))  # as JSON gives them
    assert from_dicts.timing == timing and from_dicts.gripper == gripper
    with pytest.raises(ValueError, match="grip_dwell"):
        DebridementConfig(timing={"grip_dwell": 1.0})  # a misspelt field
    with pytest.raises(ValueError, match="timing must be a PickTiming"):
        DebridementConfig(timing=0.5)
