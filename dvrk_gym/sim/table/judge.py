"""The judge of a debridement pick, from the simulator's truth (the paper's outcome table).

Each pick ends in one of the paper's outcomes:

* ``"-"`` success: the fragment lies in the receptacle;
* ``"A"`` the jaws landed too far from the fragment (a calibration miss);
* ``"B"`` the jaws were well placed, but the fragment slipped or spun out (seeds);
* ``"C"`` a raisin came up on one jaw tip (pierced) and was not delivered.

Where the jaws landed is measured when they start to close: the true closed-jaw tip
(:func:`dvrk_gym.sim.robot.kinematics.touch_point`) against where the fragment lay before the
pick, in the fragment's own axes, as a fraction of its half length and half width
(:func:`offset_ratio`; 1 is on its outline). At most WELL_PLACED_RATIO counts as well
placed; the jaws, 10 mm apart when open, then straddle the fragment across its width and
close on its middle half along its length. Beyond it, or with the closed tip above the
fragment's top (the jaws closed over it), the miss is the calibration's: a failure there
is A, including the ambiguous band where a better grasp might still have held (the
paper's rule: ambiguous A or B counts as A).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dvrk_gym.sim.physics.scene import RECEPTACLE_CENTER_M, RECEPTACLE_INNER_SIZE_M, RECEPTACLE_WALL_HEIGHT_M

SUCCESS = "-"
MISSED = "A"
SLIPPED = "B"
PIERCED = "C"
OUTCOMES = (SUCCESS, MISSED, SLIPPED, PIERCED)

WELL_PLACED_RATIO = 0.5
"""Largest normalised tip offset (see :func:`offset_ratio`) at which the jaws count as well placed."""

SCENE_LOW_M = np.array([-0.10, -0.08, -0.22])
SCENE_HIGH_M = np.array([0.18, 0.16, 0.02])
"""A fragment outside this box (base frame, metres) has left the scene: the physics failed."""


@dataclass(frozen=True)
class GripRecord:
    """Where the jaws were when they started to close on a pick's fragment.

    Attributes:
        fragment: index of the fragment the pick went for (the one nearest the jaws).
        offset_m: (along its length, across it) from its centre to the jaw tip, metres.
        ratio: :func:`offset_ratio` of that offset.
        tip: the true closed-jaw tip, (x, y, z) base frame, metres.
        above_top_m: how far the tip was above the fragment's top, metres (negative:
            below it, as it should be).
    """

    fragment: int
    offset_m: np.ndarray
    ratio: float
    tip: np.ndarray
    above_top_m: float


def fragment_offset(tip: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(along, across) offset in the paper's plane from a fragment's centre to ``tip``, metres.

    Args:
        tip: (x, y, z) base frame, metres.
        pose: the fragment's pose (4x4, base frame; body x along its length, y across).
    """
    d = np.asarray(tip, dtype=float)[:2] - pose[:2, 3]
    length_axis = pose[:2, 0] / max(np.linalg.norm(pose[:2, 0]), 1e-12)
    across_axis = np.array([-length_axis[1], length_axis[0]])
    return np.array([d @ length_axis, d @ across_axis])


def offset_ratio(offset_m: np.ndarray, size_m: np.ndarray) -> float:
    """The offset as a fraction of the fragment's half axes: sqrt((a/(L/2))^2 + (c/(W/2))^2).

    0 at its centre, 1 on its outline (the ellipse of length L and width W).
    """
    half = np.asarray(size_m, dtype=float)[:2] / 2
    return float(np.linalg.norm(np.asarray(offset_m, dtype=float) / half))


def grip_record(tip: np.ndarray, poses: list[np.ndarray], sizes: np.ndarray, candidates: list[int]) -> GripRecord | None:
    """The record of a grip: which of ``candidates`` the jaws went for, and how far off they were.

    Args:
        tip: the true closed-jaw tip when the jaws start closing, base frame, metres.
        poses: each fragment's pose before the pick (4x4, base frame).
        sizes: (n, 3) fragment sizes, metres.
        candidates: indices of the fragments that were on the paper.

    Returns:
        The record for the candidate with the smallest offset ratio, or None without candidates.
    """
    best = None
    for i in candidates:
        offset = fragment_offset(tip, poses[i])
        ratio = offset_ratio(offset, sizes[i])
        if best is None or ratio < best.ratio:
            above = float(tip[2] - pose_top(poses[i], sizes[i]))
            best = GripRecord(int(i), offset, ratio, np.array(tip, dtype=float), above)
    return best


def pose_top(pose: np.ndarray, size_m: np.ndarray) -> float:
    """Height of a lying fragment's top, base z, metres."""
    return float(pose[2, 3] + size_m[2] / 2)


def in_receptacle(position: np.ndarray) -> bool:
    """Whether a fragment centre (base frame, metres) lies inside the receptacle."""
    p = np.asarray(position, dtype=float)
    inside = np.all(np.abs(p[:2] - RECEPTACLE_CENTER_M[:2]) <= RECEPTACLE_INNER_SIZE_M / 2)
    return bool(inside and RECEPTACLE_CENTER_M[2] <= p[2] <= RECEPTACLE_CENTER_M[2] + RECEPTACLE_WALL_HEIGHT_M)


def judge(delivered: bool, pierced: bool, ratio: float, above_top_m: float = -1.0) -> str:
    """The paper's outcome of one pick.

    Args:
        delivered: the fragment ended in the receptacle.
        pierced: a jaw tip pierced it during the pick.
        ratio: how far off the jaws were when they started to close (:func:`offset_ratio`).
        above_top_m: how far the closed tip was above the fragment's top then, metres.
    """
    if delivered:
        return SUCCESS
    if pierced:
        return PIERCED
    if not np.isfinite(ratio) or ratio > WELL_PLACED_RATIO or above_top_m > 0.0:
        return MISSED
    return SLIPPED


def outcome_row(outcomes: list[str]) -> str:
    """The paper's row string, in pick order: ``"-,A,-,B,-,-,-,-"``."""
    return ",".join(outcomes)


def outcome_counts(outcomes: list[str]) -> dict[str, int]:
    """How many picks ended in each outcome: keys "success", "A", "B", "C"."""
    return {
        "success": sum(o == SUCCESS for o in outcomes),
        "A": sum(o == MISSED for o in outcomes),
        "B": sum(o == SLIPPED for o in outcomes),
        "C": sum(o == PIERCED for o in outcomes),
    }


def physics_failure(positions: np.ndarray) -> str | None:
    """A description of what is wrong with the fragments' positions, or None if nothing is.

    Args:
        positions: (n, 3) fragment centres, base frame, metres.
    """
    positions = np.asarray(positions, dtype=float)
    if not np.isfinite(positions).all():
        return "a fragment's position is not finite"
    outside = np.flatnonzero(np.any((positions < SCENE_LOW_M) | (positions > SCENE_HIGH_M), axis=1))
    if outside.size:
        return f"fragment(s) {outside.tolist()} left the scene (e.g. at {np.round(positions[outside[0]] * 1e3, 1).tolist()} mm)"
    return None


def unpicked_counts(n_fragments: int, picked: set[int], on_paper: set[int], delivered: set[int]) -> dict[str, int]:
    """The fragments of a trial that no pick went for (indices 0 .. n_fragments - 1 not in
    ``picked``), by where they are now: ``delivered`` (carried into the receptacle with
    another's pick), ``lost`` (taken off the jaws with another, or moved off the paper by
    another's pick: neither ``on_paper`` nor ``delivered``) and ``on_paper`` (left for later
    picks). Such a fragment has no outcome, so a trial's picks fall short of its fragments
    by the first two."""
    unpicked = set(range(n_fragments)) - picked
    return {"delivered": len(unpicked & delivered), "lost": len(unpicked - delivered - on_paper), "on_paper": len(unpicked & on_paper)}
