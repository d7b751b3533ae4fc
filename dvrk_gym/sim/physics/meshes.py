"""Triangle meshes built in code, for shapes PyBullet's own primitives draw wrongly.

PyBullet's TinyRenderer draws a GEOM_CYLINDER visual about 0.85 mm wider in radius than
asked (measured here: radius 2.5 mm drawn as 3.39 mm, 5 mm as 5.82 mm; boxes and spheres
are exact), which matters at 11 px/mm. These meshes are exact to their tessellation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_SEGMENTS = 48


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh: vertices (N, 3) in metres, counter-clockwise faces (M, 3), normals (N, 3)."""

    vertices: np.ndarray
    indices: np.ndarray
    normals: np.ndarray

    def visual_shape(
        self, client, rgba: tuple[float, float, float, float], position=(0.0, 0.0, 0.0), orientation=(0.0, 0.0, 0.0, 1.0)
    ) -> int:
        """Create this mesh as a PyBullet visual shape and return its id."""
        return client.createVisualShape(
            client.GEOM_MESH,
            vertices=self.vertices.tolist(),
            indices=self.indices.ravel().astype(int).tolist(),
            normals=self.normals.tolist(),
            rgbaColor=list(rgba),
            visualFramePosition=list(position),
            visualFrameOrientation=list(orientation),
        )


def _ring(radius: float, z: float, segments: int) -> np.ndarray:
    angles = 2.0 * np.pi * np.arange(segments) / segments
    return np.stack([radius * np.cos(angles), radius * np.sin(angles), np.full(segments, z)], axis=1)


def discs(centers: np.ndarray, radius_m: float, segments: int = DEFAULT_SEGMENTS) -> Mesh:
    """Flat discs facing +z, one triangle fan each, centred at ``centers`` (N, 3), metres."""
    vertices, faces = [], []
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
