"""The kinds of debridement fragment, pumpkin seed and raisin: their sizes, compliance,
friction, colour and density (:class:`FragmentType`, :data:`FRAGMENT_TYPES`).

Data only, apart from the PyBullet bodies made from it (:mod:`dvrk_gym.sim.table.fragments`),
so that settings can name the kinds without loading PyBullet. Sizes are the paper's
(:mod:`dvrk_gym.paper`); the other properties, and why, are in ``fragments``.
"""

from __future__ import annotations

from dataclasses import dataclass

from dvrk_gym import paper


@dataclass(frozen=True)
class FragmentType:
    """A kind of fragment.

    Attributes:
        name: its key in :data:`FRAGMENT_TYPES`.
        size_mean_m: mean (length, width, thickness), metres.
        size_sd_m: standard deviations of (length, width, thickness), metres.
        stiffness_n_m: its stiffness across the jaws: N per metre of squeeze.
        damping_n_s_m: its damping across the jaws, N s/m (recovery time = damping /
            stiffness).
        friction: Coulomb friction coefficient against the jaws and the paper.
        spinning_friction: torsional friction (PyBullet ``spinningFriction``), metres.
        rolling_friction: rolling friction (PyBullet ``rollingFriction``), metres.
        color_rgba: its colour (r, g, b, a) in [0, 1].
        density_kg_m3: its density, kg/m^3.
        pierce_force_n: the force (stiffness x how far in) a jaw tip pressing end-on needs
            to pierce it, N; None if it cannot be pierced.
        pierce_hold_n: the most a pierced fragment can bear before it tears off the tip, N.
    """

    name: str
    size_mean_m: tuple[float, float, float]
    size_sd_m: tuple[float, float, float]
    stiffness_n_m: float
    damping_n_s_m: float
    friction: float
    spinning_friction: float
    rolling_friction: float
    color_rgba: tuple[float, float, float, float]
    density_kg_m3: float
    pierce_force_n: float | None = None
    pierce_hold_n: float = 0.0

    @property
    def recovery_time_s(self) -> float:
        """Time constant with which it springs back after a squeeze, s."""
        return self.damping_n_s_m / self.stiffness_n_m

    @property
    def pierceable(self) -> bool:
        """Whether a jaw tip can pierce it."""
        return self.pierce_force_n is not None


FRAGMENT_TYPES: dict[str, FragmentType] = {
    # Smooth and slippery, stiff: a pumpkin seed hardly gives under the jaws.
    "pumpkin_seed": FragmentType(
        name="pumpkin_seed",
        size_mean_m=paper.PUMPKIN_SEED_SIZE_MEAN_M,
        size_sd_m=paper.PUMPKIN_SEED_SIZE_SD_M,
        stiffness_n_m=1.0e4,
        damping_n_s_m=200.0,  # springs back in 0.02 s
        friction=0.45,
        spinning_friction=1.0e-5,
        rolling_friction=1.0e-5,
        color_rgba=(0.87, 0.80, 0.62, 1.0),  # off-white beige: saturated enough to tell from paper
        density_kg_m3=1000.0,
    ),
    # Sticky and elastic, soft: a raisin squashes, grips, and a tip can go into it.
    "raisin": FragmentType(
        name="raisin",
        size_mean_m=paper.RAISIN_SIZE_MEAN_M,
        size_sd_m=paper.RAISIN_SIZE_SD_M,
        stiffness_n_m=1.5e3,
        damping_n_s_m=375.0,  # springs back in 0.25 s
        friction=1.2,
        spinning_friction=2.0e-4,
        rolling_friction=2.0e-4,
        color_rgba=(0.45, 0.28, 0.16, 1.0),  # dark brown: hue 25 deg (not the marker's red), brighter than the circles even in shade
        density_kg_m3=1300.0,
        pierce_force_n=0.15,
        pierce_hold_n=0.05,
    ),
}


def fragment_type(kind: str | FragmentType) -> FragmentType:
    """The FragmentType for a name or a FragmentType (returned as is)."""
    if isinstance(kind, FragmentType):
        return kind
    try:
        return FRAGMENT_TYPES[kind]
    except KeyError:
        raise ValueError(f"unknown fragment kind {kind!r}; expected one of {sorted(FRAGMENT_TYPES)}") from None
