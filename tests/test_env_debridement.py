"""Debridement-v0: the scene, picks judged from the truth, determinism.

What the env shows and accepts (perception, delta mode, the Gymnasium API, strict inputs,
the command line) is in test_env_debridement_interface.py, which shares this file's helpers.
"""

import json
import math

import numpy as np
import pybullet
import pytest
from conftest import SMALL, json_from_fresh_process, tool_to_tip_m

from dvrk_gym.envs.debridement import fragment_target
from dvrk_gym.envs.grid_touch import tool_pose
from dvrk_gym.envs.picks import PHASES
from dvrk_gym.evaluation.trials import Trial, totals, unpicked_note
from dvrk_gym.paper import DEBRIDEMENT_PHASE_S as PAPER_PHASE_S
from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.table import judge
from dvrk_gym.sim.table.contact import COMPLIANT
from dvrk_gym.sim.table.fragment_types import FRAGMENT_TYPES
from dvrk_gym.sim.table.fragments import TRUNCATE_SD
from dvrk_gym.sim.table.grasp import GRASP_TIP_CLEARANCE_M
from dvrk_gym.sim.table.layout import MIN_GAP_M, outline_gap

ENV_ID = "dvrk_gym/Debridement-v0"
SURFACE_Z_M = float(WORKSPACE_CENTER_M[2])


def debridement_maker(make_env):
    """A maker of Debridement envs at the small test resolution; bias "none" unless asked."""

    def _make(**kwargs):
        kwargs.setdefault("bias", "none")
        return make_env(ENV_ID, **kwargs)

    return _make


@pytest.fixture
def make(make_env):
    """Debridement envs at the small test resolution; bias "none" unless asked."""
    return debridement_maker(make_env)


def _first_on_paper(env):
    u = env.unwrapped
    return u.table.fragments[u._on_paper()[0]]


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
    return np.array([*(tip - tool_to_tip_m(yaw)), yaw], dtype=np.float32)


# ---------------------------------------------------------------------------- the scene
@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_scene_has_eight_fragments_of_the_papers_sizes_3_mm_apart_on_the_paper(make, kind):
    env = make(fragment=kind)
    env.reset(seed=4)
    fragments = env.unwrapped.table.fragments
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
        world, table = env.unwrapped.world, env.unwrapped.table
        return [np.concatenate([f.position(), f.orientation()]) for f in table.fragments], world.q_true.copy()

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
        world, table = env.unwrapped.world, env.unwrapped.table
        fragment = _first_on_paper(env)
        action = oracle_action(fragment)
        world.move_to(tool_pose(action[:3] + [0, 0, 0.01], float(action[3])), jaw_angle_rad=kin.JAW_FULLY_OPEN_RAD)
        table.move_stepped(tool_pose(action[:3] - [0, 0, 0.002], float(action[3])), min_tip_clearance_m=GRASP_TIP_CLEARANCE_M)
        assert fragment.compression() == 0.0
        table.actuate_jaws(-0.3)
        assert table.gripper.held() == {fragment.name: "grasp"}
        squeezed[kind] = fragment.compression()
        # the jaws stopped on it: open by its width less the squeeze, not closed
        assert world.jaw_angle > 0.3
        table.actuate_jaws(kin.JAW_FULLY_OPEN_RAD, 1.0)
        assert not table.gripper.held() and fragment.compression() < 0.1 * squeezed[kind]
    assert squeezed["pumpkin_seed"] > 5e-5
    assert squeezed["raisin"] > 3 * squeezed["pumpkin_seed"]


# ---------------------------------------------------------------------------- picks and the judge
@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_perfectly_calibrated_pick_delivers_the_fragment(make, kind):
    env = make(fragment=kind, contact="rigid")  # the oracle aims at the centre, not for the slide
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


def test_fragments_no_pick_went_for_are_counted_by_where_they_went(make):
    """A fragment carried off the paper by another's pick has no outcome of its own: the
    trial's info says where each such fragment went, so a cell's picks can be read against
    its fragments (here the carrying is staged: one fragment put in the receptacle, one
    off the paper, as another's pick could leave them)."""
    env = make(fragment="raisin", contact="rigid")
    env.reset(seed=0)
    _, _, _, _, info = env.step(oracle_action(_first_on_paper(env)))
    assert (info["unpicked_delivered"], info["unpicked_lost"], info["unpicked_on_paper"]) == (0, 0, 7)
    base = env.unwrapped
    carried, lost = (base.table.fragments[i] for i in base._on_paper()[:2])
    client = base.world.physics.client
    client.resetBasePositionAndOrientation(carried.body_id, judge.RECEPTACLE_CENTER_M + [0.0, 0.0, 0.004], [0, 0, 0, 1])
    client.resetBasePositionAndOrientation(lost.body_id, [0.05, -0.05, -0.15], [0, 0, 0, 1])
    _, _, _, _, info = env.step(oracle_action(_first_on_paper(env)))
    assert info["picks"] == 2 and info["fragments_on_paper"] == 4
    assert (info["unpicked_delivered"], info["unpicked_lost"], info["unpicked_on_paper"]) == (1, 1, 4)
    trial = Trial(["-", "-"], 1.0, {}, None, info["unpicked_delivered"], info["unpicked_lost"])
    assert totals([trial])["unpicked_lost"] == 1
    assert (
        unpicked_note(totals([trial]))
        == "1 fragment lost with another's pick and 1 fragment delivered with another's pick, not counted in the picks"
    )


def test_unpicked_counts_split_the_fragments_no_pick_went_for_by_where_they_are():
    counts = judge.unpicked_counts(8, picked={0, 1}, on_paper={2, 3, 4}, delivered={0, 5})  # 0 was picked: not counted
    assert counts == {"delivered": 1, "lost": 2, "on_paper": 3}  # 6 and 7 are neither on the paper nor delivered


def test_a_pick_aborted_by_a_physics_failure_counts_no_fragment_as_taken_by_another(make, monkeypatch):
    """The aborted pick is in no outcome, so where its fragment lies says nothing of other picks."""
    env = make(fragment="raisin", contact="rigid")
    env.reset(seed=0)
    base = env.unwrapped
    run = base.picker.run

    def deliver_then_fail(*arguments, **keywords):  # type: ignore[no-untyped-def]
        run(*arguments, **keywords)  # the fragment reaches the receptacle, then the physics fails
        raise pybullet.error("simulated failure")

    monkeypatch.setattr(base.picker, "run", deliver_then_fail)
    _, _, terminated, _, info = env.step(oracle_action(_first_on_paper(env)))
    assert terminated and info["sim_error"] and info["picks"] == 0
    assert (info["unpicked_delivered"], info["unpicked_lost"], info["unpicked_on_paper"]) == (0, 0, 0)
    # the same keys as a judged pick's (they were missing: info["outcome"] raised KeyError)
    judged = make(fragment="raisin", contact="rigid")
    judged.reset(seed=0)
    assert set(info) == set(judged.step(oracle_action(_first_on_paper(judged)))[4])
    assert info["outcome"] is None and info["pick_fragment"] == -1 and info["pick_time_s"] == 0.0


def test_a_pick_sent_under_the_paper_slides_its_jaws_as_a_grid_touch_does(make):
    """The jaws stall on the floor over the paper and, on the compliant paper, slide along it
    by the identified slide at the depth the command went under the paper (as GridTouch's
    touches do); on the rigid one they stall where they are. The encoders do not see it. The
    pick's grip depth takes the oracle's command under the paper."""
    tips = {}
    for contact in ("rigid", "compliant"):
        env = make(fragment="pumpkin_seed", contact=contact)
        env.reset(seed=0)
        fragment = _first_on_paper(env)
        depth = SURFACE_Z_M - (float(fragment.position()[2]) - env.unwrapped.config.timing.grip_depth_m)
        _, _, _, _, info = env.step(oracle_action(fragment))
        tips[contact] = np.asarray(info["true_tip_at_grip"], dtype=float)
    assert depth > 0.0005  # the command went more than half a millimetre under the paper
    np.testing.assert_allclose(tips["compliant"][:2] - tips["rigid"][:2], COMPLIANT.slide_m(depth), atol=1e-4)
    assert tips["compliant"][2] == pytest.approx(tips["rigid"][2], abs=1e-4)  # both on the floor


RIGID_PICKS = [
    [0.030274491834191085, 0.043179193336556045, -0.163061066239724, -0.02920058457663525, 0.03416069493177794, -0.15999376845813545],
    [0.026720134647786487, 0.04816915586813119, -0.1629271494047212, -0.022340997499077787, 0.03508829494276038, -0.15998765380543395],
]
"""Two picks sent under the rigid paper: the true jaw tip at the grip and after the drop (m), as
the test below makes them. Recorded on 7275b67, before the picks met the compliant paper, and
again when the stepped moves' wrist came to settle short once a move (it moved them 0.27 mm at
most); the rigid paper's picks have not changed otherwise."""


def test_the_rigid_paper_picks_as_before_the_picks_slid(make):
    env = make(fragment="pumpkin_seed", bias="paper", contact="rigid")
    env.reset(seed=3)
    for action, recorded in zip(([0.03, 0.04, -0.1585, 0.3], [0.025, 0.045, -0.1625, -0.5]), RIGID_PICKS, strict=True):
        _, _, _, _, info = env.step(np.array(action, dtype=np.float32))
        now = [*info["true_tip_at_grip"], *env.unwrapped.world.true_touch_point()]
        np.testing.assert_allclose(now, recorded, rtol=0.0, atol=1e-12)


def test_holding_the_tool_down_in_delta_mode_slides_the_jaws_once_not_every_step(make):
    """Each delta step sent 5 mm down from the floor slides the jaws by the slide at that depth
    under the paper (the floor lies the tip clearance over it), from where the encoders say the
    tool is, so the slide does not build up from step to step; the reported position stays put,
    and is the rigid paper's."""
    settled = {}
    for contact in ("rigid", "compliant"):
        env = make(action_mode="delta", max_steps=60, contact=contact)
        env.reset(seed=0)
        world = env.unwrapped.world
        down = np.array([0.0, 0.0, -0.005, 0.0], dtype=np.float32)
        tips, reports = [], []
        for _ in range(40):
            observation, *_ = env.step(down)
            tips.append(world.true_touch_point().copy())
            reports.append(observation["reported_pose"][:3].copy())
        tips, reports = np.array(tips[-10:]), np.array(reports[-10:])
        assert tips[:, 2].max() < SURFACE_Z_M + GRASP_TIP_CLEARANCE_M + 3e-4  # on the floor
        assert np.ptp(tips[:, :2], axis=0).max() < 2e-4 and np.ptp(reports, axis=0).max() < 1e-6  # m: no drift
        settled[contact] = tips[-1], reports[-1]
    slide = settled["compliant"][0][:2] - settled["rigid"][0][:2]
    np.testing.assert_allclose(slide, COMPLIANT.slide_m(0.005 - GRASP_TIP_CLEARANCE_M), atol=1e-5)
    np.testing.assert_allclose(settled["compliant"][1], settled["rigid"][1], atol=1e-5)  # the encoders do not see it


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
    assert env.unwrapped.table.gripper.held() == {}
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


def _rollout(env, seed: int, options=None) -> tuple[list[float], list]:
    """Reset with ``seed`` (and ``options``) and pick with the yaw of the fragment seen
    first: every observation value, and the outcome, clock and grip offset."""
    observations, outcomes = [env.reset(seed=seed, options=options)[0]], []
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


def test_cable_history_carries_across_trials_unless_relaxed(make):
    """Same seed and same history: the same trial; a seeded reset relaxes by default, as a fresh env."""

    def trial(env, options=None):
        env.reset(seed=5, options=options)
        true_start = env.unwrapped.world.true_touch_point()
        return true_start, _rollout(env, 5, options)

    def after_history(options=None):
        env = make(fragment="pumpkin_seed", bias="paper")
        _rollout(env, 8)
        return trial(env, options)

    fresh_start, fresh = trial(make(fragment="pumpkin_seed", bias="paper"))
    kept_start, kept = after_history({"relax": False})
    again_start, again = after_history({"relax": False})
    relaxed_start, relaxed = after_history()
    assert np.array_equal(kept_start, again_start) and kept == again  # same seed, same history
    assert np.linalg.norm(kept_start - fresh_start) > 1e-4  # the history moves the arm's true start
    assert np.array_equal(relaxed_start, fresh_start) and relaxed == fresh


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


# --- what a pick is judged on ---------------------------------------------------------------


def _aim_at_centre(env, index: int) -> np.ndarray:
    """The tool position at fragment ``index``'s true centre, its yaw (a review's aim)."""
    fragment = env.unwrapped.table.fragments[index]
    return np.array([*fragment.position(), (fragment.yaw() + math.pi / 2) % math.pi - math.pi / 2], dtype=np.float32)


def test_a_pick_is_judged_on_the_fragment_the_jaws_took_not_the_one_nearest_the_tip(make):
    """Aimed at fragment 1, the jaws took it and dropped it in the receptacle; the judge took
    fragment 7, nearer the tip as the jaws closed: outcome A, and 7 was set aside untouched."""
    env = make()
    env.reset(seed=0)
    env.step(_aim_at_centre(env, 0))
    _, reward, _, _, info = env.step(_aim_at_centre(env, 1))
    assert (info["pick_fragment"], info["outcome"], reward) == (1, "-", 1.0)
    assert judge.in_receptacle(env.unwrapped.table.fragments[1].position())
    assert 7 not in env.unwrapped._episode.set_aside and env.unwrapped.table.fragments[7].on_paper()


def _touch_over(env, index: int, offset_m) -> np.ndarray:
    """The command whose nominal closed-jaw tip lies 2.7 mm over fragment ``index``'s centre,
    moved by ``offset_m`` (x, y) (bias "none": the nominal tip is the true one)."""
    fragment = env.unwrapped.table.fragments[index]
    yaw = (fragment.yaw() + math.pi / 2) % math.pi - math.pi / 2
    goal = np.array([*(fragment.position()[:2] + offset_m), SURFACE_Z_M + 0.0027])
    command = goal.copy()
    for _ in range(6):
        command = command + goal - kin.touch_point(ik.inverse_kinematics(tool_pose(command, yaw)))
    return np.array([*command, yaw], dtype=np.float32)


def test_a_raisin_pierced_as_it_drops_is_outcome_c(make):
    """The pierce was recorded at the end of the first five phases only: raisin 4, pierced
    as the jaws opened over the receptacle and left on a tip, was judged A."""
    env = make(fragment="raisin")
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(5):
        _, _, _, _, info = env.step(_touch_over(env, env.unwrapped._on_paper()[0], rng.normal(0.0, 0.002, 2)))
    assert (info["pick_fragment"], info["outcome"]) == (4, "C")


def test_delta_mode_rewards_each_fragment_once(make):
    """A fragment lifted over the receptacle's rim and let fall back in scored again each time."""
    from dvrk_gym.sim.physics.scene import RECEPTACLE_CENTER_M

    env = make(action_mode="delta")
    env.reset(seed=0)
    client, fragment = env.unwrapped.world.physics.client, env.unwrapped.table.fragments[0]
    total = 0.0
    for _ in range(3):
        client.resetBasePositionAndOrientation(fragment.body_id, (RECEPTACLE_CENTER_M + [0, 0, 0.016]).tolist(), [0, 0, 0, 1])
        client.resetBaseVelocity(fragment.body_id, [0, 0, 0], [0, 0, 0])
        for _ in range(5):
            _, reward, _, _, info = env.step(np.zeros(4, dtype=np.float32))
            total += reward
    assert total == 1.0 and info["delivered"] == 1
