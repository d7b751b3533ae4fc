"""How the paper's table sent each calibrator's predictions: the authors' height rules.

The authors' records of the runs behind the paper's calibration table
(:func:`~dvrk_gym.calibration.datasets.load_paper_table_runs`) show that the networks' runs sent
each prediction as it was, but the rigid body's did not: each of its runs lifted the predicted
height by 4 to 9 mm (:data:`~dvrk_gym.paper.TABLE_LIFT_MM`; its author noted that height was
a main reason for its low performance: its predictions lay 5.5 to 8.4 mm under the paper), and
three of them first clipped it into a band of the robot's frame
(:data:`~dvrk_gym.paper.TABLE_Z_BAND_M`, :data:`~dvrk_gym.paper.TABLE_CLIPPED`). Sent
unlifted, its touches would have gone deep under the paper, where the real arm's jaws slid
along it (:mod:`dvrk_gym.sim.table.contact`).

``dvrk-gym evaluate`` touches the way the paper did (the ``"paper"`` protocol): the
:class:`HeightRule` of each setting from :func:`paper_rules`, whose band is carried over to
the simulated robot by where it reports its jaws pushed onto the circles
(:func:`carried_band`). The ``"raw"`` protocol sends every prediction as it is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dvrk_gym import paper
from dvrk_gym.utils.checks import check_float

__all__ = ["PROTOCOLS", "PROTOCOL_LINES", "RAW", "HeightRule", "RuledPolicy", "carried_band", "paper_rules"]

PROTOCOLS = ("paper", "raw")
"""``dvrk-gym evaluate``'s protocols: the authors' height rules, or the predictions as they are."""
PROTOCOL_LINES = {
    "paper": "Protocol: paper (the rigid body's heights lifted 4-9 mm and, in three settings, clipped, as the authors' runs did)",
    "raw": "Protocol: raw (every prediction sent as it is)",
}
"""What the calibration table's text says of each protocol (its first line)."""
MAX_LIFT_M = 0.05
"""Largest lift accepted, metres."""


@dataclass(frozen=True)
class HeightRule:
    """What is done to a predicted height before the robot is sent there.

    Attributes:
        band_m: (lowest, highest) height the prediction is clipped into, base frame, metres;
            None: not clipped.
        lift_m: what is then added to the height, metres.
    """

    band_m: tuple[float, float] | None
    lift_m: float

    def __post_init__(self) -> None:
        if self.band_m is not None:
            band = self.band_m
            if isinstance(band, (str, bytes)) or not isinstance(band, Sequence) or len(band) != 2:
                raise ValueError(f"band_m must be (lowest, highest) in metres, or None; got {band!r}")
            low, high = (check_float(f"band_m[{i}]", v, unit="m") for i, v in enumerate(band))
            if not low < high:
                raise ValueError(f"band_m must be (lowest, highest) with lowest < highest, got {band!r}")
            object.__setattr__(self, "band_m", (low, high))
        object.__setattr__(self, "lift_m", check_float("lift_m", self.lift_m, low=-MAX_LIFT_M, high=MAX_LIFT_M, unit="m"))

    def clipped(self, z_m: float) -> float:
        """The height ``z_m`` (m) clipped into the band (as it is without one), metres."""
        return z_m if self.band_m is None else min(max(z_m, self.band_m[0]), self.band_m[1])


RAW = HeightRule(band_m=None, lift_m=0.0)
"""The prediction as it is."""


class RuledPolicy:
    """A policy whose commanded height follows a :class:`HeightRule`; it keeps each
    prediction (m; clipped, where the rule clips, as the authors' records keep it) and what
    was sent (m).

    Args:
        policy: observation -> (bx, by, bz, yaw) in m and rad (a calibrated policy).
        rule: what is done to each predicted height.
    """

    def __init__(self, policy: Any, rule: HeightRule) -> None:
        if not isinstance(rule, HeightRule):
            raise ValueError(f"rule must be a HeightRule, got {type(rule).__name__}")
        self.policy, self.rule = policy, rule
        self.predicted: list[np.ndarray] = []
        self.sent: list[np.ndarray] = []

    def __call__(self, observation: Any) -> np.ndarray:
        action = np.array(self.policy(observation), dtype=np.float32)
        if self.rule.band_m is not None:
            action[2] = np.float32(self.rule.clipped(float(action[2])))
        self.predicted.append(action[:3].astype(np.float64))
        action[2] = np.float32(float(action[2]) + self.rule.lift_m)
        self.sent.append(action[:3].astype(np.float64))
        return action


def carried_band(pushed_heights_m: np.ndarray) -> tuple[float, float]:
    """The authors' band (:data:`~dvrk_gym.paper.TABLE_Z_BAND_M`) in the simulated robot's
    frame, metres: moved by how far the simulated robot's mean reported height with its jaws
    pushed onto the circles (``pushed_heights_m`` (n,) m, a calibration's Phase II) lies from
    theirs (:data:`~dvrk_gym.paper.TABLE_PAPER_Z_M`)."""
    heights = np.asarray(pushed_heights_m, dtype=float)
    if heights.ndim != 1 or len(heights) == 0 or not np.isfinite(heights).all():
        raise ValueError(f"pushed_heights_m must be a non-empty 1-D array of finite metres, got shape {heights.shape}")
    shift = float(np.mean(heights)) - paper.TABLE_PAPER_Z_M
    return paper.TABLE_Z_BAND_M[0] + shift, paper.TABLE_Z_BAND_M[1] + shift


def paper_rules(method: str, pushed_heights_m: np.ndarray) -> tuple[HeightRule, ...]:
    """The authors' rule for each of the table's six settings
    (:data:`~dvrk_gym.paper.CALIBRATION_SETTINGS`) of ``method`` ("RBT", "DNN" or "DNN+RF"),
    the band carried over by ``pushed_heights_m`` (:func:`carried_band`)."""
    if method not in paper.TABLE_LIFT_MM:
        raise ValueError(f"method must be one of {sorted(paper.TABLE_LIFT_MM)}, got {method!r}")
    band = carried_band(pushed_heights_m) if any(paper.TABLE_CLIPPED[method]) else None
    return tuple(
        HeightRule(band_m=band if clip else None, lift_m=1e-3 * lift)
        for lift, clip in zip(paper.TABLE_LIFT_MM[method], paper.TABLE_CLIPPED[method], strict=True)
    )


def check_rules(rules: Sequence[HeightRule], settings: int) -> None:
    """Raise ValueError unless ``rules`` holds one :class:`HeightRule` per setting."""
    if len(rules) != settings or not all(isinstance(rule, HeightRule) for rule in rules):
        raise ValueError(f"rules must hold one HeightRule per setting ({settings}), got {rules!r}")
