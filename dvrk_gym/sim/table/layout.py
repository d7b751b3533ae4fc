"""Where fragments lie: random layouts on the paper, at least a gap apart and inside its edges.

A fragment's footprint on the paper is the ellipse of its length and width. A layout is
drawn by rejection sampling: each fragment in turn gets a uniform yaw and a uniform
position that keeps its footprint inside the region and at least
:data:`MIN_GAP_M` from every footprint placed before; a fragment that finds no place
starts the layout over.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from dvrk_gym import paper
from dvrk_gym.sim.physics.scene import PHANTOM_SIZE_M, WORKSPACE_CENTER_M

MIN_GAP_M = paper.FRAGMENT_MIN_GAP_M
"""Least edge-to-edge distance between two fragments on the paper, metres."""
EDGE_MARGIN_M = 0.005
"""Fragments keep at least this far inside the phantom's edges, metres."""
_LAYOUT_SAMPLES = 128
"""Boundary points per ellipse when testing the gap between two fragments."""


def phantom_region(edge_margin_m: float = EDGE_MARGIN_M) -> tuple[np.ndarray, np.ndarray]:
    """The part of the paper fragments may cover: ((x_min, y_min), (x_max, y_max)), metres."""
    half = PHANTOM_SIZE_M[:2] / 2 - edge_margin_m
    return WORKSPACE_CENTER_M[:2] - half, WORKSPACE_CENTER_M[:2] + half


def footprint_half_extents(size: np.ndarray, yaw: float) -> np.ndarray:
    """Half extents (x, y) of the axis-aligned box around a fragment's outline, metres."""
    a, b = size[0] / 2, size[1] / 2
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([math.hypot(a * c, b * s), math.hypot(a * s, b * c)])


def ellipse_outline(size: np.ndarray, position: np.ndarray, yaw: float, samples: int = _LAYOUT_SAMPLES) -> np.ndarray:
    """Points on a fragment's outline (its ellipse on the paper), (samples, 2), metres."""
    t = 2.0 * np.pi * np.arange(samples) / samples
    local = np.stack([size[0] / 2 * np.cos(t), size[1] / 2 * np.sin(t)], axis=1)
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + position


def outline_gap(size_i, position_i, yaw_i, size_j, position_j, yaw_j) -> float:
    """A lower bound on the edge-to-edge distance between two fragment outlines, metres.

    The distance between the two sampled outlines exceeds the true one by at most half
    the spacing of the samples on each, which is subtracted; overlapping outlines give a
    negative value.
    """
    pi, pj = np.asarray(position_i, float), np.asarray(position_j, float)
    ri, rj = max(size_i[:2]) / 2, max(size_j[:2]) / 2
    centre_distance = float(np.linalg.norm(pi - pj))
    if centre_distance >= ri + rj:  # bounding circles apart: the circles' gap is a lower bound
        return centre_distance - ri - rj
    a = ellipse_outline(size_i, pi, yaw_i)
    b = ellipse_outline(size_j, pj, yaw_j)
    if _inside_ellipse(pi, size_j, pj, yaw_j) or _inside_ellipse(pj, size_i, pi, yaw_i):
        return -1.0
    if _inside_ellipse(a, size_j, pj, yaw_j).any():
        return -1.0
    spacing = 2.0 * np.pi * max(ri, rj) / _LAYOUT_SAMPLES
    sampled = float(np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)).min())
    return sampled - spacing


def _inside_ellipse(points, size, position, yaw) -> np.ndarray:
    d = np.atleast_2d(np.asarray(points, float) - position)
    c, s = math.cos(yaw), math.sin(yaw)
    u, v = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
    return (u / (size[0] / 2)) ** 2 + (v / (size[1] / 2)) ** 2 <= 1.0


def sample_layout(
    rng: np.random.Generator,
    *,
    sizes: np.ndarray,
    n: int | None = None,
    min_gap_m: float = MIN_GAP_M,
    region: tuple[Sequence[float], Sequence[float]] | None = None,
    max_tries: int = 2000,
) -> tuple[np.ndarray, np.ndarray]:
    """Random positions and orientations for fragments on the paper, by rejection sampling.

    Each fragment's outline (the ellipse of its length and width) lies entirely inside
    ``region`` and at least ``min_gap_m`` from every other outline. Yaws are uniform.

    Args:
        rng: the generator to draw from.
        sizes: (n, 3) sizes from :func:`sample_fragment_sizes`, metres.
        n: how many to place (default: all rows of ``sizes``).
        min_gap_m: least edge-to-edge distance, metres.
        region: ((x_min, y_min), (x_max, y_max)) the outlines must stay in, metres,
            base frame; default: the phantom inset by :data:`EDGE_MARGIN_M`.
        max_tries: draws allowed per fragment before starting the layout over; the
            whole layout is attempted at most 20 times.

    Returns:
        positions (n, 2) in metres (base frame x, y) and yaws (n,) in radians, in
        [-pi/2, pi/2): the angle of each fragment's length axis from base x.

    Raises:
        ValueError: if no layout was found (the region is too small for the fragments).
    """
    sizes = np.asarray(sizes, dtype=float)
    n = len(sizes) if n is None else int(n)
    if n > len(sizes):
        raise ValueError(f"n = {n} fragments asked for but only {len(sizes)} sizes given")
    low, high = (np.asarray(v, dtype=float) for v in (region or phantom_region()))
    for _ in range(20):
        positions: list[Any] = []
        yaws: list[Any] = []
        for i in range(n):
            placed = _place_one(rng, sizes[i], sizes[:i], positions, yaws, low, high, min_gap_m, max_tries)
            if placed is None:
                break
            positions.append(placed[0])
            yaws.append(placed[1])
        else:
            return np.array(positions).reshape(n, 2), np.array(yaws, dtype=float)
    raise ValueError(
        f"could not place {n} fragments at least {min_gap_m * 1e3:.1f} mm apart inside the region "
        f"{np.round(low * 1e3, 1).tolist()} - {np.round(high * 1e3, 1).tolist()} mm after 20 attempts; "
        "use fewer fragments, a smaller gap or a larger region"
    )


def _place_one(rng, size, placed_sizes, positions, yaws, low, high, min_gap_m, max_tries):
    for _ in range(max_tries):
        yaw = float(rng.uniform(-np.pi / 2, np.pi / 2))
        half = footprint_half_extents(size, yaw)
        if np.any(high - low < 2 * half):
            continue
        position = rng.uniform(low + half, high - half)
        if all(outline_gap(size, position, yaw, s, p, y) >= min_gap_m for s, p, y in zip(placed_sizes, positions, yaws)):
            return position, yaw
    return None
