"""The printed grid's detections: kept per scene and camera in the process, and exactly what
two fresh renders give."""

import dataclasses

import numpy as np
import pytest

from dvrk_gym.sim.endoscope import printed_grid
from dvrk_gym.sim.endoscope.camera import StereoCamera
from dvrk_gym.sim.endoscope.printed_grid import detect_printed_grid
from dvrk_gym.sim.world import HOME_JOINTS, DvrkWorld, WorldConfig

RESOLUTION = (480, 270)


@pytest.fixture
def counted_renders(monkeypatch):
    """Clears the cache and counts the world's full-frame renders."""
    printed_grid.clear_cache()
    calls = []
    real = DvrkWorld.render

    def render(self, side="left"):
        calls.append(side)
        return real(self, side)

    monkeypatch.setattr(DvrkWorld, "render", render)
    yield calls
    printed_grid.clear_cache()


def _fresh_detections(world: DvrkWorld):
    """The grid detected from two new renders, the tool retracted, without any cache."""
    world.robot.set_joints(HOME_JOINTS, 0.0)
    return detect_printed_grid(world.camera, world.render("left"), world.render("right"))


def _as_arrays(grid):
    return [np.concatenate([d.left_uv, d.right_uv, d.camera_position, [d.left_area_px, d.right_area_px]]) for d in grid]


def _same(a, b) -> bool:
    return all(np.array_equal(x, y, equal_nan=True) for x, y in zip(_as_arrays(a), _as_arrays(b))) and len(a) == len(b)


def test_a_second_world_of_the_same_scene_reads_the_first_ones_detections_bit_for_bit(counted_renders):
    first = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION))
    second = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION, pixel_noise_px=0.5))  # noise is applied later, not here
    try:
        grid = first.observe_grid()
        assert counted_renders == ["left", "right"]
        assert second.observe_grid() is grid and counted_renders == ["left", "right"]
        assert sum(d.seen_both for d in grid) == 35
        assert _same(grid, _fresh_detections(second))
    finally:
        first.close()
        second.close()


def test_another_camera_is_detected_afresh(counted_renders):
    base = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION))
    pose = base.camera.pose.copy()
    pose[0, 3] += 0.002
    others = [
        DvrkWorld(WorldConfig(camera_resolution=(640, 360))),
        DvrkWorld(WorldConfig(camera_resolution=RESOLUTION, camera_pose=pose)),
    ]
    try:
        grid = base.observe_grid()
        for world in others:
            before = len(counted_renders)
            other = world.observe_grid()
            assert len(counted_renders) == before + 2
            assert other is not grid and _same(other, _fresh_detections(world))
        moved = _as_arrays(others[1].observe_grid())[0][:2] - _as_arrays(grid)[0][:2]
        assert np.abs(moved).max() > 1.0  # the moved camera sees the circles elsewhere
    finally:
        base.close()
        for world in others:
            world.close()


def test_a_camera_that_triangulates_with_another_baseline_is_not_served_the_cached_positions(counted_renders):
    """The renders do not depend on the baseline the triangulation assumes, the positions do."""
    world = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION))
    try:
        camera = world.camera
        other = StereoCamera(
            camera.intrinsics, baseline_m=camera.baseline_m, pose=camera.pose, calibrated_baseline_m=1.1 * camera.calibrated_baseline_m
        )
        render_both = world._render_retracted
        first = printed_grid.observe_printed_grid(camera, "scene", render_both)
        second = printed_grid.observe_printed_grid(other, "scene", render_both)
        assert len(counted_renders) == 4 and second is not first
        assert second[0].camera_position[2] == pytest.approx(1.1 * first[0].camera_position[2], rel=1e-9)
        assert printed_grid.observe_printed_grid(camera, "scene", render_both) is first
    finally:
        world.close()


def test_instruments_share_the_detections_while_their_links_are_the_same(counted_renders):
    """The presets' instruments differ in their cables, not in their links' geometry (the
    arm's body is built from the true DH table), so they see the same grid; a world whose
    arm were built from another table would not share it."""
    worlds = [
        DvrkWorld(WorldConfig(camera_resolution=RESOLUTION, bias=bias, bias_seed=seed))
        for bias, seed in (("paper", 0), ("paper", 1), ("severe", 3))
    ]
    try:
        grids = [world.observe_grid() for world in worlds]
        assert len(counted_renders) == 2 and grids[1] is grids[0] and grids[2] is grids[0]
        assert _same(grids[2], _fresh_detections(worlds[2]))
        key = worlds[0]._grid_scene_key()
        worlds[0].cable.true_dh = (dataclasses.replace(worlds[0].cable.true_dh[0], a_m=0.001),) + worlds[0].cable.true_dh[1:]
        assert worlds[0]._grid_scene_key() != key
    finally:
        for world in worlds:
            world.close()


def test_a_scene_with_other_bodies_is_never_cached(counted_renders):
    plain = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION))
    world = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION))
    try:
        assert plain.observe_grid()[0].seen_both and len(counted_renders) == 2
        c = world.physics.client  # a white card over circle 0
        card = c.createVisualShape(c.GEOM_BOX, halfExtents=[0.006, 0.006, 0.0005], rgbaColor=[1.0, 1.0, 1.0, 1.0])
        centre = printed_grid.grid_circle_centers()[0] + [0.0, 0.0, 0.002]
        world.physics.add("card", c.createMultiBody(0.0, -1, card, basePosition=centre.tolist()))
        covered = world.observe_grid()
        assert len(counted_renders) == 4  # rendered: not the plain scene's detections
        assert not covered[0].seen_left and not covered[0].seen_right and covered[1].seen_both
        world._grid_cache = None  # the world's own memo: ask again
        world.observe_grid()
        assert len(counted_renders) == 6  # rendered again, not read from the cache
    finally:
        world.close()
        plain.close()


def test_the_shared_detections_cannot_be_written(counted_renders):
    world = DvrkWorld(WorldConfig(camera_resolution=RESOLUTION))
    try:
        detection = world.observe_grid()[0]
        for array in (detection.left_uv, detection.right_uv, detection.camera_position):
            with pytest.raises(ValueError, match="read-only"):
                array[0] = 0.0
    finally:
        world.close()


def test_the_cache_keeps_at_most_its_size(counted_renders, monkeypatch):
    monkeypatch.setattr(printed_grid, "CACHE_SIZE", 2)
    worlds = [DvrkWorld(WorldConfig(camera_resolution=resolution)) for resolution in ((480, 270), (320, 180), (640, 360))]
    try:
        for world in worlds:
            world.observe_grid()
        assert len(printed_grid._CACHE) == 2
        worlds[0]._grid_cache = None
        worlds[0].observe_grid()  # the oldest was dropped: rendered again
        assert len(counted_renders) == 8
    finally:
        for world in worlds:
            world.close()
