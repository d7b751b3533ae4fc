"""The debridement fragments: pumpkin seeds and raisins on the paper.

A fragment is one rigid ellipsoid (a convex hull) with a compliance of its own: a
Kelvin-Voigt element across the jaws (``stiffness_n_m``, ``damping_n_s_m``). While the
jaws hold it they close past where they first touched it by grip force / stiffness, so
they really reach into its hull by its compression (see :mod:`dvrk_gym.sim.table.grasp`);
:meth:`Fragment.compression` tracks that squeeze, and after release it springs back
with the time constant damping / stiffness (a raisin slowly, a seed at once).

Why not a deformable body: measured here, PyBullet's soft bodies at this scale either
fall through the paper (classic mass-spring world at 1x and 5x world scale; at 10x it
sinks 3 mm into the phantom and the jaws pass through it), explode (deformable-world
mass-spring, any scale), or run at about 11 steps/s for eight fragments
(deformable-world FEM at 10x, which also wobbles at rest). Why not PyBullet's soft
contact (``contactStiffness``): squeezed between a jaw and the paper a 0.1 g body
cannot push back with more than about 0.1 N, so it sank 1 mm into the paper.

Two details matter at millimetre scale:

* Bullet pads a convex hull by its collision margin, 1 mm by default, which would make a
  2.4 mm seed float 1 mm above the paper. The margin is set to
  :data:`COLLISION_MARGIN_M` and the hull is shrunk by it, so the padded hull is the
  ellipsoid.
* A fragment weighs about 0.1 g, too light for the contact solver to pass a grip of a
  newton through it, so holding is not left to friction alone; see
  :mod:`dvrk_gym.sim.table.grasp`.

Sizes follow the paper's table (mm, mean +- sd, length x width x thickness): pumpkin
seed 12.4+-0.8 x 6.8+-0.3 x 2.4+-0.3; raisin 12.3+-1.5 x 5.9+-1.1 x 4.2+-0.5. Where the
fragments lie on the paper is drawn by :mod:`dvrk_gym.sim.table.layout`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_gym import paper
from dvrk_gym.sim.physics import meshes
from dvrk_gym.sim.physics.client import Physics
from dvrk_gym.sim.physics.scene import WORKSPACE_CENTER_M
from dvrk_gym.sim.table.fragment_types import FragmentType, fragment_type
from dvrk_gym.sim.table.layout import phantom_region

COLLISION_MARGIN_M = 1.0e-4
"""Collision margin of a fragment's hull (Bullet's default, 1 mm, is half a seed)."""

TRUNCATE_SD = 3.0
"""Sizes are drawn from normals truncated at this many standard deviations."""

FRAGMENTS_PER_TRIAL = paper.FRAGMENTS_PER_TRIAL
"""Fragments on the paper in one of the paper's trials."""

_HULL_RINGS = 8
_HULL_SEGMENTS = 16
_VISUAL_RINGS = 12
_VISUAL_SEGMENTS = 24
_SPAWN_CLEARANCE_M = 1.0e-5
"""Fragments are created this far above the paper, so they start just out of contact."""


# ---------------------------------------------------------------------------- sampling
def sample_fragment_sizes(kind: str | FragmentType, rng: np.random.Generator, n: int = FRAGMENTS_PER_TRIAL) -> np.ndarray:
    """Draw fragment sizes from the paper's table.

    Each dimension is normal with the table's mean and sd, truncated at
    :data:`TRUNCATE_SD` sd (redrawn until inside, so always positive), independently, so
    each follows the table. About 8 % of raisins come out thicker than wide (4.2+-0.5
    against 5.9+-1.1 mm); they lie as drawn, as a lumpy raisin does.

    Args:
        kind: "pumpkin_seed", "raisin" or a FragmentType.
        rng: the generator to draw from.
        n: how many fragments.

    Returns:
        (n, 3) sizes (length, width, thickness), metres.
    """
    spec = fragment_type(kind)
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    mean, sd = np.array(spec.size_mean_m), np.array(spec.size_sd_m)
    z = rng.standard_normal((n, 3))
    while True:
        bad = np.abs(z) > TRUNCATE_SD
        if not bad.any():
            break
        z[bad] = rng.standard_normal(int(bad.sum()))
    return mean + z * sd


# ---------------------------------------------------------------------------- bodies
def _unit_sphere(rings: int, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (poles first) and outward-facing triangles of a UV sphere of radius 1."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2.0 * np.pi * np.arange(segments) / segments
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    ring_points = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1).reshape(-1, 3)
    vertices = np.vstack([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], ring_points])
    k = np.arange(segments)
    nxt = (k + 1) % segments
    faces = [np.stack([np.zeros(segments, int), 2 + k, 2 + nxt], axis=1)]
    for r in range(rings - 2):
        a, b = 2 + r * segments, 2 + (r + 1) * segments
        faces.append(np.stack([a + k, b + k, b + nxt], axis=1))
        faces.append(np.stack([a + k, b + nxt, a + nxt], axis=1))
    last = 2 + (rings - 2) * segments
    faces.append(np.stack([np.ones(segments, int), last + nxt, last + k], axis=1))
    return vertices, np.vstack(faces)


def ellipsoid_mesh(semi_axes_m: np.ndarray, rings: int = _VISUAL_RINGS, segments: int = _VISUAL_SEGMENTS) -> meshes.Mesh:
    """A triangle mesh of an ellipsoid with semi-axes (a, b, c) along x, y, z, metres."""
    semi = np.asarray(semi_axes_m, dtype=float)
    unit, faces = _unit_sphere(rings, segments)
    normals = unit / semi**2
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return meshes.Mesh(unit * semi, faces, normals)


class Fragment:
    """One fragment in the world.

    Args:
        physics: the world it lives in.
        name: its body name in ``physics``.
        kind: what it is.
        size_m: (length, width, thickness), metres.
        position: (x, y) of its centre on the paper, metres, base frame.
        yaw: angle of its length axis from base x, radians.
    """

    def __init__(self, physics: Physics, *, name: str, kind: FragmentType, size_m: np.ndarray, position: np.ndarray, yaw: float) -> None:
        self.physics = physics
        self.name = name
        self.kind = kind
        self.size_m = np.array(size_m, dtype=float)
        if self.size_m.shape != (3,) or not np.all(self.size_m > 2 * COLLISION_MARGIN_M):
            raise ValueError(f"size_m must be 3 lengths > {2 * COLLISION_MARGIN_M} m, got {size_m!r}")
        self.semi_axes_m = self.size_m / 2
        self.mass_kg = float(kind.density_kg_m3 * 4.0 / 3.0 * np.pi * np.prod(self.semi_axes_m))
        """Its mass, kg."""
        self._compression_m = 0.0
        self.body_id = physics.add(name, self._build(np.asarray(position, dtype=float), float(yaw)))

    def _build(self, position: np.ndarray, yaw: float) -> int:
        c = self.physics.client
        unit, _ = _unit_sphere(_HULL_RINGS, _HULL_SEGMENTS)
        hull = unit * (self.semi_axes_m - COLLISION_MARGIN_M)  # the margin pads it back out
        collision = meshes.convex_hull_shape(c, hull)
        visual = self.physics.mesh_visual(ellipsoid_mesh(self.semi_axes_m), self.kind.color_rgba)
        z = WORKSPACE_CENTER_M[2] + self.semi_axes_m[2] + _SPAWN_CLEARANCE_M
        orientation = Rotation.from_euler("z", yaw).as_quat()
        body = c.createMultiBody(
            self.mass_kg,
            collision,
            visual,
            basePosition=[float(position[0]), float(position[1]), float(z)],
            baseOrientation=[float(v) for v in orientation],
        )
        c.changeDynamics(
            body,
            -1,
            collisionMargin=COLLISION_MARGIN_M,
            lateralFriction=self.kind.friction,
            spinningFriction=self.kind.spinning_friction,
            rollingFriction=self.kind.rolling_friction,
        )
        return body

    # ------------------------------------------------------------------ state
    def position(self) -> np.ndarray:
        """Its centre (x, y, z), metres, base frame."""
        return np.array(self.physics.client.getBasePositionAndOrientation(self.body_id)[0])

    def orientation(self) -> np.ndarray:
        """Its orientation as a quaternion (x, y, z, w)."""
        return np.array(self.physics.client.getBasePositionAndOrientation(self.body_id)[1])

    def pose(self) -> np.ndarray:
        """Its pose (4x4, metres, base frame); the body axes are (length, width, thickness)."""
        position, quaternion = self.physics.client.getBasePositionAndOrientation(self.body_id)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat(quaternion).as_matrix()
        pose[:3, 3] = position
        return pose

    def yaw(self) -> float:
        """Angle of its longer axis in the paper's plane from base x, radians in [-pi/2, pi/2)."""
        axis = self.pose()[:3, 0 if self.size_m[0] >= self.size_m[1] else 1]
        angle = math.atan2(axis[1], axis[0])
        return (angle + np.pi / 2) % np.pi - np.pi / 2

    def compression(self) -> float:
        """How far it is squeezed, metres: the jaws' summed indentation, relaxing after release."""
        return self._compression_m

    def update_compression(self, indentation_m: float, dt_s: float) -> None:
        """Advance the compression state by one step given the jaws' indentation now.

        It follows a deeper squeeze at once and springs back towards a shallower one
        with the kind's recovery time (a raisin slowly, a seed at once).
        """
        if indentation_m >= self._compression_m:
            self._compression_m = float(indentation_m)
        else:
            decay = math.exp(-dt_s / self.kind.recovery_time_s)
            self._compression_m = float(indentation_m + (self._compression_m - indentation_m) * decay)

    def outward_normal(self, point: np.ndarray) -> np.ndarray:
        """The ellipsoid's outward unit normal nearest ``point`` (base frame, metres)."""
        pose = self.pose()
        local = pose[:3, :3].T @ (np.asarray(point, dtype=float) - pose[:3, 3])
        normal = local / self.semi_axes_m**2
        norm = np.linalg.norm(normal)
        if norm == 0.0:
            return pose[:3, 2].copy()
        return pose[:3, :3] @ (normal / norm)

    def on_paper(self, tolerance_m: float = 0.001) -> bool:
        """Whether it lies on the paper (its centre over the phantom, at resting height)."""
        p = self.position()
        low, high = phantom_region(0.0)
        over = bool(np.all(p[:2] >= low) and np.all(p[:2] <= high))
        return over and abs(p[2] - WORKSPACE_CENTER_M[2] - self.semi_axes_m[2]) < tolerance_m


def spawn_fragments(
    physics: Physics,
    *,
    kind: str | FragmentType,
    sizes: np.ndarray,
    positions: np.ndarray,
    yaws: np.ndarray,
    name_prefix: str = "fragment",
) -> list[Fragment]:
    """Create fragments lying flat on the paper, named "fragment_0", "fragment_1", ...

    Args:
        physics: the world to create them in.
        kind: "pumpkin_seed", "raisin" or a FragmentType.
        sizes: (n, 3) (length, width, thickness), metres.
        positions: (n, 2) centres (x, y) on the paper, metres, base frame.
        yaws: (n,) angles of their length axes from base x, radians.
        name_prefix: body names are ``f"{name_prefix}_{i}"``.
    """
    spec = fragment_type(kind)
    sizes = np.asarray(sizes, dtype=float).reshape(-1, 3)
    positions = np.asarray(positions, dtype=float).reshape(-1, 2)
    yaws = np.asarray(yaws, dtype=float).reshape(-1)
    if not (len(sizes) == len(positions) == len(yaws)):
        raise ValueError(f"sizes, positions and yaws must have one row per fragment; got {len(sizes)}, {len(positions)}, {len(yaws)}")
    return [
        Fragment(physics, name=f"{name_prefix}_{i}", kind=spec, size_m=size, position=position, yaw=yaw)
        for i, (size, position, yaw) in enumerate(zip(sizes, positions, yaws))
    ]
