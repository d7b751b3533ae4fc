"""The paper under the grid, as the jaws meet it: where a touch sent under it ends.

A touch commanded ``depth`` under the point where the jaws first meet the paper does not stop
there, nor go through. On the real robot (the authors' records of their table's runs,
:data:`dvrk_gym.sim.identified.PAPER_CONTACT`) the arm went on down, stopping short of its
command by ``give * depth`` (held off by the paper: its reported height lies that far over
the command), and the jaws, held on the paper, slid along it by ``slide_per_depth * depth``.
The model gives where the jaws touch (GridTouch-v0's ``true_tip_position`` and what the
endoscope sees); the arm's joints and its PyBullet body follow the command, so a rendered
touch under the paper shows the jaws through it, as the world's own ``true_touch_point`` puts them.
Debridement-v0's picks meet the same paper: their jaws stall on a floor just over it and
slide along it by :meth:`PaperContact.slide_m` of the depth their command goes under the paper
(:class:`~dvrk_gym.sim.table.table.DebridementTable`), so a command slides the jaws as far in
either env.
:class:`PaperContact` is that model; :data:`COMPLIANT` has the identified values and
:data:`RIGID` stops at first contact, reporting all the depth, without sliding (the
simulator before the records were read); ``CONTACTS`` names them for the envs' ``contact``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dvrk_gym.sim.identified import PAPER_CONTACT
from dvrk_gym.utils.checks import check_float

__all__ = ["COMPLIANT", "CONTACTS", "DEFAULT_CONTACT", "PaperContact", "RIGID"]

MAX_SLIDE_PER_DEPTH = 5.0
"""Largest slide per depth accepted, metres per metre."""


@dataclass(frozen=True)
class PaperContact:
    """How a touch sent under the paper ends.

    Attributes:
        slide_per_depth: (2,) how far the jaws slide along the robot's x and y per metre
            the command goes under first contact, metres per metre.
        give: the share of that depth by which the arm gives way: it stops that far short of
            its command, held off by the paper, in [0, 1] (1: it stops at first contact, as
            on a paper that does not yield).

    Raises ValueError for a slide that is not two finite numbers within
    :data:`MAX_SLIDE_PER_DEPTH`, or a give outside [0, 1] (bools are not numbers here).
    """

    slide_per_depth: tuple[float, float]
    give: float

    def __post_init__(self) -> None:
        if (
            isinstance(self.slide_per_depth, (str, bytes))
            or not isinstance(self.slide_per_depth, Sequence)
            or len(self.slide_per_depth) != 2
        ):
            raise ValueError(f"slide_per_depth must be two numbers (x, y) in m/m, got {self.slide_per_depth!r}")
        bound = MAX_SLIDE_PER_DEPTH
        slide = tuple(
            check_float(f"slide_per_depth[{i}]", v, low=-bound, high=bound, unit="m/m") for i, v in enumerate(self.slide_per_depth)
        )
        object.__setattr__(self, "slide_per_depth", slide)
        object.__setattr__(self, "give", check_float("give", self.give, low=0.0, high=1.0))

    def command_height(self, contact_z_m: float, target_z_m: float) -> float:
        """Where the arm's command ends, metres: ``target_z_m`` if the jaws would not reach
        the paper before it (``contact_z_m``, the command's height at first contact, is not
        over it), else ``give`` of the depth short of it."""
        depth = contact_z_m - target_z_m
        if depth <= 0.0:
            return target_z_m
        return contact_z_m if self.give == 1.0 else target_z_m + self.give * depth

    def touch_point(self, tip_m: np.ndarray, depth_m: float, surface_z_m: float) -> np.ndarray:
        """Where the jaws touch, (3,) m: the true tip ``tip_m`` (3,) m of an arm whose command
        went ``depth_m`` under first contact, held on the paper at ``surface_z_m`` and slid
        along it. A depth of 0 or less gives the tip as it is; so does a contact without give
        or slide (the arm stopped where the jaws met the paper)."""
        if depth_m <= 0.0 or self == RIGID:
            return tip_m
        z = float(tip_m[2]) if self.give == 1.0 else surface_z_m
        slide = self.slide_m(depth_m)
        return np.array([tip_m[0] + slide[0], tip_m[1] + slide[1], z])

    @property
    def slides(self) -> bool:
        """Whether the jaws slide at all under a command below the paper."""
        return self.slide_per_depth != (0.0, 0.0)

    def slide_m(self, depth_m: float) -> np.ndarray:
        """How far the jaws slide along the robot's x and y, (2,) m, under a command ``depth_m``
        metres below first contact (none at a depth of 0 or less). Raises ValueError for a
        depth that is not a finite number."""
        depth = max(check_float("depth_m", depth_m, unit="m"), 0.0)
        return np.array([self.slide_per_depth[0] * depth, self.slide_per_depth[1] * depth])


COMPLIANT = PaperContact(slide_per_depth=PAPER_CONTACT.slide_per_depth, give=PAPER_CONTACT.give)
"""The paper as the authors' records show it (:data:`dvrk_gym.sim.identified.PAPER_CONTACT`)."""
RIGID = PaperContact(slide_per_depth=(0.0, 0.0), give=1.0)
"""A paper that does not yield: the arm stops at first contact (give 1), and the jaws do not slide."""
CONTACTS = {"compliant": COMPLIANT, "rigid": RIGID}
"""GridTouch-v0's and Debridement-v0's ``contact`` choices."""
DEFAULT_CONTACT = "compliant"
"""Both envs' default ``contact``: the identified paper."""
