"""Triangle meshes built in code, for shapes PyBullet's own primitives draw wrongly.

PyBullet's TinyRenderer draws a GEOM_CYLINDER visual about 0.85 mm wider in radius than
asked (measured here: radius 2.5 mm drawn as 3.39 mm, 5 mm as 5.82 mm; boxes and spheres
are exact), which matters at 11 px/mm. These meshes are exact to their tessellation.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

DEFAULT_SEGMENTS = 48


class PyBulletLists:
    """The Python lists handed to PyBullet's shape calls, kept and refilled in place.

    pybullet 3.2 keeps a reference to every list given to it as a mesh's vertices, indices or
    normals, and to each of its rows, so a fresh list per call is never freed (measured with
    psutil's RSS: 0.87 MB each time the printed grid is built, about 2 MB per Debridement-v0
    reset, growing without bound). The same list objects, refilled with each call's numbers,
    cost nothing more per call; the numbers in them are freed as usual. A lock keeps two
    threads from refilling a list while PyBullet reads it.
    """

    def __init__(self) -> None:
        self._lists: dict[tuple[str, tuple[int, ...]], list] = {}
        self._lock = threading.Lock()

    @contextmanager
    def filled(self) -> Iterator[Callable[[str, np.ndarray], list]]:
        """Hold the lock; yield ``fill(role, array)``, which returns the kept list for that
        role and shape, refilled with ``array``'s numbers (rows of a 2-D array as lists)."""
        with self._lock:
            yield self._fill

    def _fill(self, role: str, array: np.ndarray) -> list:
        array = np.asarray(array)
        rows = array.tolist()
        key = (role, array.shape)
        held = self._lists.get(key)
        if held is None:
            self._lists[key] = rows
            return rows
        if array.ndim == 1:
            held[:] = rows
        else:
            for target, row in zip(held, rows):
                target[:] = row
        return held


PYBULLET_LISTS = PyBulletLists()
"""The one set of kept lists of this process (every physics client shares it)."""


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh: vertices (N, 3) in metres, counter-clockwise faces (M, 3), normals (N, 3)."""

    vertices: np.ndarray
    indices: np.ndarray
    normals: np.ndarray

    def visual_shape(
        self, client, rgba: tuple[float, float, float, float], position=(0.0, 0.0, 0.0), orientation=(0.0, 0.0, 0.0, 1.0)
    ) -> int:
        """Create this mesh as a PyBullet visual shape and return its id (its lists are :data:`PYBULLET_LISTS`').

        A body's meshes go through :meth:`dvrk_gym.sim.physics.client.Physics.mesh_visual`,
        which calls this and remembers the mesh, so that a display mirror can draw it too.
        """
        with PYBULLET_LISTS.filled() as fill:
            return client.createVisualShape(
                client.GEOM_MESH,
                vertices=fill("visual.vertices", self.vertices),
                indices=fill("visual.indices", self.indices.ravel().astype(int)),
                normals=fill("visual.normals", self.normals),
                rgbaColor=list(rgba),
                visualFramePosition=list(position),
                visualFrameOrientation=list(orientation),
            )

    def obj_text(self) -> str:
        """This mesh as the text of a Wavefront OBJ file (vertices and normals in metres, 1-based faces)."""
        lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in self.vertices.tolist()]
        lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in self.normals.tolist()]
        lines += [f"f {a}//{a} {b}//{b} {c}//{c}" for a, b, c in (self.indices.reshape(-1, 3) + 1).tolist()]
        return "\n".join(lines) + "\n"


def convex_hull_shape(client: Any, vertices: np.ndarray) -> int:
    """A PyBullet convex-hull collision shape of ``vertices`` (N, 3), metres; returns its id
    (the list is :data:`PYBULLET_LISTS`')."""
    with PYBULLET_LISTS.filled() as fill:
        return client.createCollisionShape(client.GEOM_MESH, vertices=fill("hull.vertices", vertices))


def _ring(radius: float, z: float, segments: int) -> np.ndarray:
    angles = 2.0 * np.pi * np.arange(segments) / segments
    return np.stack([radius * np.cos(angles), radius * np.sin(angles), np.full(segments, z)], axis=1)


def discs(centers: np.ndarray, radius_m: float, segments: int = DEFAULT_SEGMENTS) -> Mesh:
    """Flat discs facing +z, one triangle fan each, centred at ``centers`` (N, 3), metres."""
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    for center in np.asarray(centers, dtype=float):
        base = len(vertices) * (segments + 1)
        vertices.append(np.vstack([center, center + _ring(radius_m, 0.0, segments)]))
        k = np.arange(segments)
        faces.append(np.stack([np.full(segments, base), base + 1 + k, base + 1 + (k + 1) % segments], axis=1))
    points = np.vstack(vertices)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    return Mesh(points, np.vstack(faces), normals)


def cylinder(radius_m: float, length_m: float, segments: int = DEFAULT_SEGMENTS) -> Mesh:
    """A closed cylinder along z, centred at the origin (metres)."""
    half = length_m / 2
    bottom, top = _ring(radius_m, -half, segments), _ring(radius_m, half, segments)
    side_normals = np.vstack([bottom[:, :2] / radius_m, bottom[:, :2] / radius_m])
    side_normals = np.hstack([side_normals, np.zeros((2 * segments, 1))])
    k = np.arange(segments)
    nxt = (k + 1) % segments
    side = np.vstack([np.stack([k, nxt, segments + k], axis=1), np.stack([nxt, segments + nxt, segments + k], axis=1)])
    # Caps get their own vertices so their normals point along the axis.
    cap_base = 2 * segments
    top_center, bottom_center = cap_base, cap_base + segments + 1
    top_ring = top_center + 1 + k
    bottom_ring = bottom_center + 1 + k
    top_faces = np.stack([np.full(segments, top_center), top_ring, top_center + 1 + nxt], axis=1)
    bottom_faces = np.stack([np.full(segments, bottom_center), bottom_center + 1 + nxt, bottom_ring], axis=1)
    vertices = np.vstack([bottom, top, [[0, 0, half]], top, [[0, 0, -half]], bottom])
    normals = np.vstack(
        [
            side_normals,
            np.tile([0.0, 0.0, 1.0], (segments + 1, 1)),
            np.tile([0.0, 0.0, -1.0], (segments + 1, 1)),
        ]
    )
    return Mesh(vertices, np.vstack([side, top_faces, bottom_faces]), normals)


def box(size_m: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Mesh:
    """A box of full sizes ``size_m`` (x, y, z), centred at the origin (metres): four
    vertices and two triangles per face, each face with its own normal."""
    half = np.asarray(size_m, dtype=float) / 2
    vertices: list[np.ndarray] = []
    normals: list[np.ndarray] = []
    faces: list[Any] = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            corners = []
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                corner = normal.copy()
                corner[u], corner[v] = a, b
                corners.append(corner * half)
            base = len(vertices)
            vertices += corners
            normals += [normal] * 4
            quad = [(base, base + 1, base + 2), (base, base + 2, base + 3)]
            faces += quad if sign > 0 else [(i, k, j) for i, j, k in quad]  # counter-clockwise seen from outside
    return Mesh(np.array(vertices), np.array(faces), np.array(normals))
