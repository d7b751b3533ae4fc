"""The workspace: a silicone phantom under white paper printed with 35 circles, a receptacle.

All positions are in the robot base frame (origin at the remote centre of motion, z up),
in metres, where the paper's own data put the workspace (its rows span bx 5-70 mm,
by 11-74 mm, bz -170 to -158 mm): the phantom covers bx 2.5-77.5 mm and by 4.5-79.5 mm,
and the paper's top surface is at bz = -0.164 m.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from dvrk_gym.sim.physics import meshes
from dvrk_gym.sim.physics.client import Physics

WORKSPACE_CENTER_M = np.array([0.040, 0.042, -0.164])
"""Centre of the paper's top surface, (x, y, z) in metres, base frame."""

PHANTOM_SIZE_M = np.array([0.075, 0.075, 0.010])
"""Silicone phantom extent, (x, y, z) in metres."""

PAPER_THICKNESS_M = 0.0003
GRID_ROWS = 5
GRID_COLUMNS = 7
GRID_PITCH_M = np.array([0.0100, 0.0125])
"""Centre-to-centre spacing of the printed circles along (x, y), in metres."""
CIRCLE_RADIUS_M = 0.0025
CIRCLE_PRINT_HEIGHT_M = 0.00005
"""How far the printed discs are drawn above the paper (keeps them in front in the z-buffer)."""
PRINT_TOP_Z_M = float(WORKSPACE_CENTER_M[2]) + CIRCLE_PRINT_HEIGHT_M
"""The plane of the printed discs, base frame z in metres: from a camera above it, nothing
above it can lie behind a disc."""

RECEPTACLE_CENTER_M = np.array([-0.022, 0.042, -0.172])
"""Centre of the receptacle's floor top, (x, y, z) in metres: left of the phantom, in view."""
RECEPTACLE_INNER_SIZE_M = np.array([0.026, 0.030])
RECEPTACLE_WALL_HEIGHT_M = 0.014
RECEPTACLE_WALL_THICKNESS_M = 0.0015

TRAY_TOP_Z_M = -0.180
"""Top of the dark tray everything stands on, in metres."""

PHANTOM_CONTACT_STIFFNESS_N_M = 3.0e3
"""Silicone compliance: about 0.3 mm of indentation per newton."""
PHANTOM_CONTACT_DAMPING_N_S_M = 40.0

WHITE = (0.95, 0.95, 0.93, 1.0)
BLACK = (0.03, 0.03, 0.03, 1.0)
SILICONE = (0.85, 0.62, 0.55, 1.0)
RECEPTACLE_BLUE = (0.25, 0.40, 0.70, 1.0)
TRAY_GREY = (0.30, 0.30, 0.32, 1.0)


def grid_circle_centers() -> np.ndarray:
    """The centres of the 35 printed circles on the paper's surface.

    Returns:
        (35, 3) positions in metres, base frame, row-major: row r (along y) then
        column c (along x), so index = r * 7 + c.
    """
    cols = (np.arange(GRID_COLUMNS) - (GRID_COLUMNS - 1) / 2) * GRID_PITCH_M[0]
    rows = (np.arange(GRID_ROWS) - (GRID_ROWS - 1) / 2) * GRID_PITCH_M[1]
    yy, xx = np.meshgrid(rows, cols, indexing="ij")
    offsets = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    return WORKSPACE_CENTER_M + offsets


@dataclass(frozen=True)
class SceneBodies:
    """PyBullet ids of the workspace bodies (also registered by name in Physics)."""

    tray: int
    phantom: int
    paper: int
    grid: int
    receptacle: int


def build_scene(physics: Physics) -> SceneBodies:
    """Create the tray, phantom, paper, printed grid and receptacle in ``physics``.

    Surfaces that can never be seen are left out of the visuals (not the collision
    shapes): the tray under the phantom and the phantom's top under the paper. The
    software renderer shades every surface it draws, so each hidden layer would cost
    about 0.6 ms per 60 x 60 window (measured) for identical pixels.
    """
    tray_size = np.array([0.30, 0.22, 0.004])
    tray_center = np.array([0.03, 0.042, TRAY_TOP_Z_M - 0.002])
    tray_visual = _frame_visual(physics, tray_size, tray_center, PHANTOM_SIZE_M[:2], WORKSPACE_CENTER_M[:2], TRAY_GREY)
    tray = _box(physics, "tray", tray_size, tray_center, TRAY_GREY, visual=tray_visual)
    phantom_top = WORKSPACE_CENTER_M[2] - PAPER_THICKNESS_M
    phantom_center = WORKSPACE_CENTER_M.copy()
    phantom_center[2] = phantom_top - PHANTOM_SIZE_M[2] / 2
    phantom_visual = _walls_visual(physics, PHANTOM_SIZE_M, SILICONE)
    phantom = _box(physics, "phantom", PHANTOM_SIZE_M, phantom_center, SILICONE, visual=phantom_visual)
    physics.client.changeDynamics(
        phantom,
        -1,
        contactStiffness=PHANTOM_CONTACT_STIFFNESS_N_M,
        contactDamping=PHANTOM_CONTACT_DAMPING_N_S_M,
        lateralFriction=0.8,
    )
    paper_center = WORKSPACE_CENTER_M - [0.0, 0.0, PAPER_THICKNESS_M / 2]
    paper_size = [PHANTOM_SIZE_M[0], PHANTOM_SIZE_M[1], PAPER_THICKNESS_M]
    paper = _box(physics, "paper", paper_size, paper_center, WHITE)
    physics.client.changeDynamics(paper, -1, lateralFriction=0.5)
    grid = _printed_grid(physics)
    receptacle = _receptacle(physics)
    return SceneBodies(tray, phantom, paper, grid, receptacle)


def _box(physics: Physics, name: str, size, center, rgba, visual: int | None = None) -> int:
    """A static box; ``visual`` replaces the box's own visual shape when given."""
    c = physics.client
    half = [float(s) / 2 for s in size]
    col = c.createCollisionShape(c.GEOM_BOX, halfExtents=half)
    vis = c.createVisualShape(c.GEOM_BOX, halfExtents=half, rgbaColor=rgba) if visual is None else visual
    body = c.createMultiBody(0.0, col, vis, basePosition=[float(v) for v in center])
    return physics.add(name, body)


def _boxes_visual(physics: Physics, half_extents: list, positions: list, rgba) -> int:
    n = len(half_extents)
    return physics.client.createVisualShapeArray(
        shapeTypes=[physics.client.GEOM_BOX] * n,
        halfExtents=[[float(v) for v in h] for h in half_extents],
        rgbaColors=[rgba] * n,
        visualFramePositions=[[float(v) for v in p] for p in positions],
    )


def _frame_visual(physics: Physics, size, center, hole_size, hole_center, rgba) -> int:
    """A box's visual with a rectangular hole (where something else covers it), body frame."""
    x0, x1 = center[0] - size[0] / 2, center[0] + size[0] / 2
    y0, y1 = center[1] - size[1] / 2, center[1] + size[1] / 2
    hx0, hx1 = hole_center[0] - hole_size[0] / 2, hole_center[0] + hole_size[0] / 2
    hy0, hy1 = hole_center[1] - hole_size[1] / 2, hole_center[1] + hole_size[1] / 2
    rects = [(x0, hx0, y0, y1), (hx1, x1, y0, y1), (hx0, hx1, y0, hy0), (hx0, hx1, hy1, y1)]
    half = [[(b - a) / 2, (d - c) / 2, size[2] / 2] for a, b, c, d in rects]
    positions = [[(a + b) / 2 - center[0], (c + d) / 2 - center[1], 0.0] for a, b, c, d in rects]
    return _boxes_visual(physics, half, positions, rgba)


def _walls_visual(physics: Physics, size, rgba) -> int:
    """The four side walls of a box (its top and bottom are never seen), body frame."""
    wall = 0.0002
    sx, sy, sz = (float(v) / 2 for v in size)
    half = [[wall, sy, sz], [wall, sy, sz], [sx, wall, sz], [sx, wall, sz]]
    positions = [[-sx + wall, 0, 0], [sx - wall, 0, 0], [0, -sy + wall, 0], [0, sy - wall, 0]]
    return _boxes_visual(physics, half, positions, rgba)


def _printed_grid(physics: Physics) -> int:
    """The 35 circles as one visual-only mesh (printing adds no collision geometry)."""
    centers = grid_circle_centers() + [0.0, 0.0, CIRCLE_PRINT_HEIGHT_M]
    visual = physics.mesh_visual(meshes.discs(centers, CIRCLE_RADIUS_M), BLACK)
    return physics.add("grid", physics.client.createMultiBody(0.0, -1, visual))


@contextmanager
def printed_circles_hidden(physics: Physics, grid: int) -> Iterator[None]:
    """Leave the printed circles (body ``grid``) out of TinyRenderer's images while inside:
    it skips a shape of alpha 0, which makes a small window about a third cheaper to render.
    Only for a render whose subject lies above :data:`PRINT_TOP_Z_M` as the camera does, so
    that no disc could have hidden any of it."""
    physics.client.changeVisualShape(grid, -1, rgbaColor=[0.0, 0.0, 0.0, 0.0])
    try:
        yield
    finally:
        physics.client.changeVisualShape(grid, -1, rgbaColor=list(BLACK))


def _receptacle(physics: Physics) -> int:
    """An open box: a floor and four walls, as one static body."""
    c = physics.client
    inner_x, inner_y = RECEPTACLE_INNER_SIZE_M
    t, h = RECEPTACLE_WALL_THICKNESS_M, RECEPTACLE_WALL_HEIGHT_M
    outer_x, outer_y = inner_x + 2 * t, inner_y + 2 * t
    half_extents = [
        [outer_x / 2, outer_y / 2, t / 2],  # floor
        [t / 2, outer_y / 2, h / 2],  # -x wall
        [t / 2, outer_y / 2, h / 2],  # +x wall
        [inner_x / 2, t / 2, h / 2],  # -y wall
        [inner_x / 2, t / 2, h / 2],  # +y wall
    ]
    positions = [
        [0.0, 0.0, -t / 2],
        [-(inner_x + t) / 2, 0.0, h / 2],
        [(inner_x + t) / 2, 0.0, h / 2],
        [0.0, -(inner_y + t) / 2, h / 2],
        [0.0, (inner_y + t) / 2, h / 2],
    ]
    n = len(half_extents)
    col = c.createCollisionShapeArray(shapeTypes=[c.GEOM_BOX] * n, halfExtents=half_extents, collisionFramePositions=positions)
    vis = c.createVisualShapeArray(
        shapeTypes=[c.GEOM_BOX] * n,
        halfExtents=half_extents,
        rgbaColors=[RECEPTACLE_BLUE] * n,
        visualFramePositions=positions,
    )
    body = c.createMultiBody(0.0, col, vis, basePosition=[float(v) for v in RECEPTACLE_CENTER_M])
    return physics.add("receptacle", body)
