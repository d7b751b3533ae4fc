"""The workspace: phantom, paper, grid of circles, receptacle; independent physics servers."""

import numpy as np
import pybullet
import pytest

from dvrk_gym.sim.physics import scene
from dvrk_gym.sim.physics.client import Physics, PhysicsError


@pytest.fixture
def physics():
    world = Physics()
    yield world
    world.close()


def test_grid_has_35_circles_in_5_rows_of_7_on_the_paper():
    centers = scene.grid_circle_centers()
    assert centers.shape == (35, 3)
    np.testing.assert_allclose(centers[:, 2], scene.WORKSPACE_CENTER_M[2])
    np.testing.assert_allclose(np.diff(centers[:7, 0]), scene.GRID_PITCH_M[0])
    np.testing.assert_allclose(centers[7::7, 1] - centers[:28:7, 1], scene.GRID_PITCH_M[1])
    half = scene.PHANTOM_SIZE_M[:2] / 2 - scene.CIRCLE_RADIUS_M
    assert np.all(np.abs(centers[:, :2] - scene.WORKSPACE_CENTER_M[:2]) < half)


def test_workspace_is_where_the_paper_data_put_it():
    centers = scene.grid_circle_centers()
    # The authors' Phase I rows span bx 5-70 mm, by 11-74 mm, bz -170 to -158 mm.
    assert centers[:, 0].min() >= 0.005 and centers[:, 0].max() <= 0.075
    assert centers[:, 1].min() >= 0.005 and centers[:, 1].max() <= 0.080
    assert -0.170 <= scene.WORKSPACE_CENTER_M[2] <= -0.158


def test_receptacle_is_outside_the_phantom(physics):
    bodies = scene.build_scene(physics)
    lo, hi = physics.client.getAABB(bodies.receptacle)
    phantom_lo, phantom_hi = physics.client.getAABB(bodies.phantom)
    assert hi[0] < phantom_lo[0] or lo[0] > phantom_hi[0] or hi[1] < phantom_lo[1] or lo[1] > phantom_hi[1]


def test_paper_top_is_at_the_workspace_height_and_phantom_is_compliant(physics):
    bodies = scene.build_scene(physics)
    _, paper_hi = physics.client.getAABB(bodies.paper)
    assert paper_hi[2] == pytest.approx(scene.WORKSPACE_CENTER_M[2], abs=1e-4)  # AABB margin
    info = physics.client.getDynamicsInfo(bodies.phantom, -1)
    contact_stiffness, contact_damping = info[9], info[8]
    assert contact_stiffness == pytest.approx(scene.PHANTOM_CONTACT_STIFFNESS_N_M)
    assert contact_damping == pytest.approx(scene.PHANTOM_CONTACT_DAMPING_N_S_M)


def test_bodies_are_named_and_unknown_names_are_clear_errors(physics):
    scene.build_scene(physics)
    assert set(physics.body_names) == {"tray", "phantom", "paper", "grid", "receptacle"}
    with pytest.raises(PhysicsError, match="no body named 'nope'"):
        physics.body("nope")


def test_two_physics_servers_do_not_see_each_other():
    a, b = Physics(), Physics()
    try:
        scene.build_scene(a)
        assert a.client.getNumBodies() == 5
        assert b.client.getNumBodies() == 0
    finally:
        a.close()
        b.close()


def test_closed_server_refuses_use_and_closes_twice_safely():
    world = Physics()
    world.close()
    world.close()
    with pytest.raises(PhysicsError, match="closed"):
        world.client


def test_gui_without_display_warns_and_runs_headless(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.warns(RuntimeWarning, match="needs a display"):
        world = Physics(gui=True)
    try:
        assert world.client.getConnectionInfo()["connectionMethod"] == pybullet.DIRECT
    finally:
        world.close()
