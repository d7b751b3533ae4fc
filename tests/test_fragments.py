"""Fragments on the paper, what the jaws do to them (grasp.py) with the real PSMBody, and the table
that owns both beside a world (table.py)."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from dvrk_gym.sim.endoscope import detection as perception
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M, build_scene
from dvrk_gym.sim.robot import ik
from dvrk_gym.sim.robot import kinematics as kin
from dvrk_gym.sim.robot.body import PSMBody
from dvrk_gym.sim.table.contact import COMPLIANT
from dvrk_gym.sim.table.fragment_types import FRAGMENT_TYPES
from dvrk_gym.sim.table.fragments import sample_fragment_sizes, spawn_fragments
from dvrk_gym.sim.table.grasp import GRASP_TIP_CLEARANCE_M, JAW_LINKS, Gripper
from dvrk_gym.sim.table.layout import MIN_GAP_M, ellipse_outline, phantom_region, sample_layout
from dvrk_gym.sim.table.table import DebridementTable
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

PAPER_TABLE_MM = {  # (length, width, thickness): mean, sd
    "pumpkin_seed": ((12.4, 6.8, 2.4), (0.8, 0.3, 0.3)),
    "raisin": ((12.3, 5.9, 4.2), (1.5, 1.1, 0.5)),
}


@pytest.fixture
def world():
    physics = Physics()
    build_scene(physics)
    robot = PSMBody(physics)
    yield physics, robot
    physics.close()


def _tool_pose(tip_xy, tip_z, yaw):
    """Tool pose (paper orientation for ``yaw``) that puts the closed jaw tip at (xy, z)."""
    pitch, roll = kin.paper_pitch_roll(yaw)
    pose = kin.pose_from_euler(WORKSPACE_CENTER_M + [0.0, 0.0, 0.01], yaw, pitch, roll)
    q = ik.inverse_kinematics(pose)
    offset = kin.jaw_tip_positions(q, 0.0)[0] - pose[:3, 3]
    pose[:3, 3] = np.array([tip_xy[0], tip_xy[1], tip_z]) - offset
    return pose


def _closing_direction(yaw):
    """Unit (x, y) direction the jaws close along for tool yaw ``yaw``."""
    q = ik.inverse_kinematics(_tool_pose(WORKSPACE_CENTER_M[:2], WORKSPACE_CENTER_M[2], yaw))
    axis = kin.link_frames(q)[5][:3, 0]
    return axis[:2] / np.linalg.norm(axis[:2])


def _fragment_across_jaws(physics, kind, offset_across=0.0, offset_along=0.0, tool_yaw=0.0):
    """One mean-sized fragment at the workspace centre, its length across the closing
    direction; returns it and where the closed tip should go (offsets in metres)."""
    closing = _closing_direction(tool_yaw)
    yaw = math.atan2(closing[1], closing[0]) + math.pi / 2
    center = WORKSPACE_CENTER_M[:2]
    size = np.array(FRAGMENT_TYPES[kind].size_mean_m)
    (fragment,) = spawn_fragments(physics, kind=kind, sizes=size[None], positions=center[None], yaws=[yaw])
    length_axis = np.array([math.cos(yaw), math.sin(yaw)])
    return fragment, center + offset_across * closing + offset_along * length_axis


def _lower_and_close(gripper, fragment, tip_xy, tool_yaw=0.0):
    top = WORKSPACE_CENTER_M[2]
    above = _tool_pose(tip_xy, top + fragment.size_m[2] + 0.004, tool_yaw)
    gripper.place(ik.inverse_kinematics(above), kin.JAW_FULLY_OPEN_RAD)
    gripper.move_tool(_tool_pose(tip_xy, top + GRASP_TIP_CLEARANCE_M, tool_yaw), 0.02)
    gripper.command_jaw(-0.2)
    gripper.settle_jaws(240)


def _raise(gripper, tip_xy, height_m, tool_yaw=0.0):
    top = WORKSPACE_CENTER_M[2]
    gripper.move_tool(_tool_pose(tip_xy, top + GRASP_TIP_CLEARANCE_M + height_m, tool_yaw), 0.03)


# ---------------------------------------------------------------------------- sizes
@pytest.mark.parametrize("kind", sorted(PAPER_TABLE_MM))
def test_sizes_follow_the_papers_table(kind):
    sizes = sample_fragment_sizes(kind, np.random.default_rng(0), 20000) * 1e3
    mean, sd = (np.array(v) for v in PAPER_TABLE_MM[kind])
    assert np.all(sizes > 0)
    np.testing.assert_allclose(sizes.mean(axis=0), mean, atol=0.05 * sd.max())
    np.testing.assert_allclose(sizes.std(axis=0), sd, rtol=0.05)


def test_sizes_come_from_the_generator_only():
    a = sample_fragment_sizes("raisin", np.random.default_rng(3), 8)
    b = sample_fragment_sizes("raisin", np.random.default_rng(3), 8)
    np.testing.assert_array_equal(a, b)


def test_unknown_kind_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="pumpkin_seed"):
        sample_fragment_sizes("almond", np.random.default_rng(0), 1)


# ---------------------------------------------------------------------------- layout
def _dense_gap(size_i, p_i, yaw_i, size_j, p_j, yaw_j):
    """Edge-to-edge distance of two outlines sampled every ~10 um (never below the truth)."""
    a = ellipse_outline(size_i, p_i, yaw_i, samples=4096)
    b = ellipse_outline(size_j, p_j, yaw_j, samples=4096)
    return float(cKDTree(b).query(a)[0].min())


@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_layout_keeps_fragments_apart_and_on_the_phantom(kind):
    low, high = phantom_region()
    for seed in range(5):
        rng = np.random.default_rng(seed)
        sizes = sample_fragment_sizes(kind, rng, 8)
        positions, yaws = sample_layout(rng, sizes=sizes)
        assert positions.shape == (8, 2) and yaws.shape == (8,)
        for i in range(8):
            outline = ellipse_outline(sizes[i], positions[i], yaws[i], samples=512)
            assert np.all(outline >= low - 1e-9) and np.all(outline <= high + 1e-9)
            for j in range(i):
                circles_gap = np.linalg.norm(positions[i] - positions[j]) - (sizes[i, 0] + sizes[j, 0]) / 2
                if circles_gap >= MIN_GAP_M:  # even their bounding circles are far enough apart
                    continue
                gap = _dense_gap(sizes[i], positions[i], yaws[i], sizes[j], positions[j], yaws[j])
                assert gap >= MIN_GAP_M - 2e-6, (seed, i, j, gap)


def test_layout_that_cannot_fit_says_so():
    rng = np.random.default_rng(0)
    sizes = sample_fragment_sizes("pumpkin_seed", rng, 8)
    tiny = (WORKSPACE_CENTER_M[:2] - 0.01, WORKSPACE_CENTER_M[:2] + 0.01)
    with pytest.raises(ValueError, match="could not place 8 fragments"):
        sample_layout(rng, sizes=sizes, region=tiny, max_tries=50)


# ---------------------------------------------------------------------------- bodies
def test_fragments_are_named_and_report_their_pose(world):
    physics, _ = world
    sizes = np.array([FRAGMENT_TYPES["raisin"].size_mean_m] * 2)
    fragments = spawn_fragments(physics, kind="raisin", sizes=sizes, positions=[[0.03, 0.04], [0.05, 0.04]], yaws=[0.3, -1.2])
    assert [f.name for f in fragments] == ["fragment_0", "fragment_1"]
    assert physics.body("fragment_1") == fragments[1].body_id
    np.testing.assert_allclose(fragments[0].position()[:2], [0.03, 0.04], atol=1e-9)
    assert fragments[0].yaw() == pytest.approx(0.3)
    assert fragments[1].yaw() == pytest.approx(-1.2)
    assert fragments[0].compression() == 0.0


@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_fragments_rest_on_the_paper_without_drifting(world, kind):
    physics, _ = world
    rng = np.random.default_rng(7)
    sizes = sample_fragment_sizes(kind, rng, 8)
    positions, yaws = sample_layout(rng, sizes=sizes)
    fragments = spawn_fragments(physics, kind=kind, sizes=sizes, positions=positions, yaws=yaws)
    physics.step(24)  # settle the 10 um spawn clearance
    start = np.array([f.position() for f in fragments])
    physics.step(480)  # 2 s
    end = np.array([f.position() for f in fragments])
    assert np.abs(end - start).max() < 1e-4
    resting_z = WORKSPACE_CENTER_M[2] + sizes[:, 2] / 2
    np.testing.assert_allclose(end[:, 2], resting_z, atol=3e-5)
    assert all(f.on_paper() for f in fragments)


def test_colours_are_neither_marker_red_nor_paper_white_nor_circle_black():
    pixels = np.array([[[round(255 * v) for v in t.color_rgba[:3]] for t in FRAGMENT_TYPES.values()]], dtype=np.uint8)
    for shade in (1.0, 0.6):  # lit and in shadow
        shaded = (pixels * shade).astype(np.uint8)
        assert not perception.red_mask(shaded).any()
        grey = shaded.astype(float) @ [0.299, 0.587, 0.114]
        assert np.all(grey > perception.DARK_MAX_VALUE)
    saturation = 1 - pixels.min(axis=-1) / pixels.max(axis=-1)
    assert np.all(saturation > 0.25)  # white paper has about 0.02


# ---------------------------------------------------------------------------- jaws
def _jaw_overlap(physics, robot, fragment):
    """How far the jaw boxes reach into the fragment's rigid hull, summed, m (geometry)."""
    depths = []
    for link in JAW_LINKS:
        points = physics.client.getClosestPoints(robot.body_id, fragment.body_id, 0.001, linkIndexA=link)
        depths.append(max([-p[8] for p in points], default=0.0))
    return sum(max(d, 0.0) for d in depths)


def _squeeze(physics, robot, kind):
    fragment, tip = _fragment_across_jaws(physics, kind)
    gripper = Gripper(physics, robot, [fragment])
    _lower_and_close(gripper, fragment, tip)
    squeezed, overlap = fragment.compression(), _jaw_overlap(physics, robot, fragment)
    gripper.command_jaw(kin.JAW_FULLY_OPEN_RAD)
    for _ in range(240):  # 1 s: the jaws open in 0.3 s, the fragment springs back
        gripper.step()
    return squeezed, overlap, fragment.compression(), gripper


def test_jaws_compress_a_raisin_more_than_a_seed_and_both_recover(world):
    physics, robot = world
    seed, seed_overlap, seed_after, _ = _squeeze(physics, robot, "pumpkin_seed")
    physics.reset()
    build_scene(physics)
    raisin, raisin_overlap, raisin_after, gripper = _squeeze(physics, PSMBody(physics), "raisin")
    assert seed > 5e-5 and raisin > 3 * seed
    # it is geometric: the jaws reach about that far into the rigid hull (the compression is
    # measured along the jaws' arcs, the overlap along the contact normal, plus contact slop)
    for compression, overlap in ((seed, seed_overlap), (raisin, raisin_overlap)):
        assert 0.5 * compression <= overlap <= 2.5 * compression + 1e-4
    assert seed_after < 0.1 * seed and raisin_after < 0.1 * raisin
    assert not gripper.held()


@pytest.mark.parametrize("kind", ["pumpkin_seed", "raisin"])
def test_well_centred_grasp_lifts_the_fragment_10_mm_and_lets_go_when_opened(world, kind):
    physics, robot = world
    fragment, tip = _fragment_across_jaws(physics, kind)
    gripper = Gripper(physics, robot, [fragment])
    start = fragment.position()
    _lower_and_close(gripper, fragment, tip)
    assert gripper.held() == {fragment.name: "grasp"}
    _raise(gripper, tip, 0.010)
    assert fragment.position()[2] - start[2] > 0.009
    gripper.command_jaw(kin.JAW_FULLY_OPEN_RAD)
    for _ in range(120):
        gripper.step()
    assert not gripper.held()
    assert fragment.position()[2] == pytest.approx(start[2], abs=1e-4)  # fell back onto the paper


def test_jaws_closing_5_mm_away_leave_the_fragment_alone(world):
    physics, robot = world
    # the jaws (2.6 mm wide along the fragment's length) end 5 mm past its end
    fragment, tip = _fragment_across_jaws(physics, "raisin", offset_along=0.00615 + 0.0013 + 0.005)
    gripper = Gripper(physics, robot, [fragment])
    physics.step(24)
    start = fragment.position()
    _lower_and_close(gripper, fragment, tip)
    _raise(gripper, tip, 0.010)
    assert not gripper.held()
    assert np.abs(fragment.position() - start).max() < 1e-5


def test_seed_squeezed_near_its_end_slips_out_but_a_raisin_holds(world):
    physics, robot = world
    seed, tip = _fragment_across_jaws(physics, "pumpkin_seed", offset_along=0.0045)
    gripper = Gripper(physics, robot, [seed])
    _lower_and_close(gripper, seed, tip)
    _raise(gripper, tip, 0.010)
    assert not gripper.held() and seed.position()[2] < WORKSPACE_CENTER_M[2] + 0.002
    physics.reset()
    build_scene(physics)
    robot = PSMBody(physics)
    raisin, tip = _fragment_across_jaws(physics, "raisin", offset_along=0.0045)
    gripper = Gripper(physics, robot, [raisin])
    _lower_and_close(gripper, raisin, tip)
    _raise(gripper, tip, 0.010)
    assert gripper.held() == {raisin.name: "grasp"}


def test_tip_pressing_on_a_raisin_pierces_it_and_it_stays_on_the_open_jaw(world):
    physics, robot = world
    raisin, tip = _fragment_across_jaws(physics, "raisin", offset_across=-0.006)  # upper tip over its top
    gripper = Gripper(physics, robot, [raisin])
    _lower_and_close(gripper, raisin, tip)
    _raise(gripper, tip, 0.010)
    assert gripper.held() == {raisin.name: "pierce"}
    assert raisin.position()[2] > WORKSPACE_CENTER_M[2] + 0.006
    gripper.command_jaw(kin.JAW_FULLY_OPEN_RAD)
    for _ in range(120):
        gripper.step()
    assert gripper.held() == {raisin.name: "pierce"}  # failure mode C: it does not drop


def test_a_held_fragment_is_carried_by_a_free_space_move(world):
    physics, robot = world
    fragment, tip = _fragment_across_jaws(physics, "pumpkin_seed")
    gripper = Gripper(physics, robot, [fragment])
    _lower_and_close(gripper, fragment, tip)
    _raise(gripper, tip, 0.010)
    before = fragment.position() - kin.forward_kinematics(gripper.q)[:3, 3]
    gripper.place(ik.inverse_kinematics(_tool_pose(tip - 0.02, WORKSPACE_CENTER_M[2] + 0.015, 0.0)))
    after = fragment.position() - kin.forward_kinematics(gripper.q)[:3, 3]
    np.testing.assert_allclose(after, before, atol=1e-6)
    gripper.step()
    assert gripper.held() == {fragment.name: "grasp"}


def _trial_positions(seed):
    physics = Physics()
    try:
        build_scene(physics)
        robot = PSMBody(physics)
        rng = np.random.default_rng(seed)
        sizes = sample_fragment_sizes("pumpkin_seed", rng, 8)
        positions, yaws = sample_layout(rng, sizes=sizes)
        fragments = spawn_fragments(physics, kind="pumpkin_seed", sizes=sizes, positions=positions, yaws=yaws)
        gripper = Gripper(physics, robot, fragments)
        for fragment in fragments[:2]:
            p = fragment.position()
            yaw = float(kin.nearest_paper_yaw(fragment.yaw()))
            target = p[:2] + rng.normal(0.0, 0.001, 2)
            _lower_and_close(gripper, fragment, target, yaw)
            _raise(gripper, target, 0.010, yaw)
            gripper.command_jaw(kin.JAW_FULLY_OPEN_RAD)
            gripper.settle_jaws(120)
        physics.step(60)
        return np.array([f.position() for f in fragments] + [f.orientation() for f in fragments], dtype=object)
    finally:
        physics.close()


def test_same_seed_gives_bit_identical_fragment_positions():
    a, b = _trial_positions(11), _trial_positions(11)
    for x, y in zip(a, b):
        assert np.array_equal(np.asarray(x, float), np.asarray(y, float))


def test_table_drives_the_worlds_jaws_until_the_world_is_rebuilt():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(320, 180)))
    try:
        with pytest.raises(ValueError, match="contact must be a PaperContact"):
            DebridementTable(world, contact="compliant")
        table = DebridementTable(world)
        assert table.contact is COMPLIANT  # the identified paper, as GridTouch-v0's default
        assert world.jaw_driver is None and table.held() == {} and table.true_fragment_positions().shape == (0, 3)
        with pytest.raises(RuntimeError, match="add_fragments"):
            table.actuate_jaws(0.5)
        rng = np.random.default_rng(0)
        table.add_fragments("raisin", rng, n=2)
        assert world.jaw_driver is table and len(table.fragments) == 2 and table.true_fragment_positions().shape == (2, 3)
        with pytest.raises(RuntimeError, match="rebuild"):
            DebridementTable(world).add_fragments("raisin", rng, n=2)
        world.move_joints(world.q_cmd, jaw_angle_rad=0.4)  # a free-space move goes through the gripper
        assert world.jaw_angle == pytest.approx(table.gripper.jaw_angle) == pytest.approx(0.4)
        world.rebuild()
        assert world.jaw_driver is None and table.fragments == [] and table.gripper is None
        assert len(table.add_fragments("pumpkin_seed", rng, n=3)) == 3
    finally:
        world.close()


def test_a_table_refuses_waits_moves_and_fragments_it_cannot_make():
    world = DvrkWorld(WorldConfig(bias="none", camera_resolution=(320, 180)))
    try:
        table = DebridementTable(world)
        for n, rng in ((10**10, np.random.default_rng(0)), (8.0, np.random.default_rng(0)), (-1, np.random.default_rng(0)), (2, 0)):
            with pytest.raises(ValueError, match="n must be|rng must be"):
                table.add_fragments("raisin", rng, n=n)  # 10**10 tried to allocate 224 GiB
        assert world.jaw_driver is None  # nothing laid
        table.add_fragments("raisin", np.random.default_rng(0), n=2)
        clock = world.clock.time_s
        for call in (
            lambda: table.dwell(1e7),  # hung
            lambda: table.dwell(float("nan")),
            lambda: table.actuate_jaws(0.5, duration_s=1e7),
            lambda: table.actuate_jaws(0.5, duration_s=-1.0),
            lambda: table.actuate_jaws(float("nan")),
            lambda: table.move_stepped(world.reported_pose(), duration_s=1e7),  # tried 2.4e9 waypoints
            lambda: table.move_stepped(world.reported_pose(), duration_s=0.0),
            lambda: table.move_stepped(world.reported_pose(), min_tip_clearance_m=float("nan")),  # turned the floor off
        ):
            with pytest.raises(ValueError, match="seconds|duration_s|jaw_angle_rad|min_tip_clearance_m"):
                call()
        assert world.clock.time_s == clock
        assert table.dwell(-0.05) == 0.0  # what is left of an overrun phase: no wait
        for index in (-1, 2, 1.0):  # -1 parked the last fragment a slot below the first
            with pytest.raises(ValueError, match="index must be an int in \\[0, 1\\]"):
                table.set_aside_fragment(index)
    finally:
        world.close()


def test_a_table_keeps_the_world_it_sits_on():
    """``DebridementTable(DvrkWorld(...))`` on one line: the table is all that holds the world."""
    table = DebridementTable(DvrkWorld(WorldConfig(bias="none", camera_resolution=(320, 180))))
    try:
        assert len(table.add_fragments("raisin", np.random.default_rng(0), n=2)) == 2
    finally:
        table.world.close()
