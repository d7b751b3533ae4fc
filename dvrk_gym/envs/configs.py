"""The settings of the environments, as frozen dataclasses: :class:`EnvConfig` (what every
env shares), :class:`ExplorationConfig` and :class:`GridTouchConfig`
(:class:`~dvrk_gym.envs.debridement_config.DebridementConfig` is in its own module).

This module, like ``debridement_config``, loads neither PyBullet nor SciPy: registering the
envs reads these defaults into each id's ``gym.spec(id).kwargs`` when ``dvrk_gym`` is
imported (:mod:`dvrk_gym.envs`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from dvrk_gym import paper
from dvrk_gym.sim.endoscope.noise import MAX_PIXEL_NOISE_PX
from dvrk_gym.sim.endoscope.renderers import DISPLAY_RENDERERS
from dvrk_gym.sim.robot.bias import BIAS_PRESETS, BiasConfig
from dvrk_gym.sim.table.contact import CONTACTS, DEFAULT_CONTACT
from dvrk_gym.utils.checks import check_choice, check_endoscope_resolution, check_float_fields, check_int_fields, check_resolution

REWARD_TYPES = ("dense", "sparse")
"""GridTouch-v0's rewards: "dense" (minus the goal distance in millimetres) or "sparse"."""


@dataclass(frozen=True)
class EnvConfig:
    """Settings every environment shares.

    Attributes:
        bias: cable bias, a preset name ("none", "paper", "severe"), a BiasConfig or a dict of
            its fields (as ``dataclasses.asdict`` gives them).
        bias_seed: which instrument to draw from the bias distribution (fixed for the
            life of the env; episodes are seeded separately through ``reset(seed=...)``).
        camera_resolution: (width, height) of each endoscope image, pixels.
        pixel_noise_px: standard deviation of the detection noise added to every pixel
            coordinate the cameras report, at 1920 x 1080 (scaled with the resolution).
        render_resolution: (width, height) of the images ``render()`` returns, pixels; None:
            ``camera_resolution``. Only what is shown changes: the detections keep their
            images at ``camera_resolution``.
        renderer: what draws ``render()``'s images: "auto" (PyBullet's EGL renderer when it
            runs here, 3.1-4.6x less CPU at 1920 x 1080, else TinyRenderer, with one log line saying why),
            "egl" (an error if it cannot run) or "tiny" (TinyRenderer: at
            ``camera_resolution``, the detections' very pixels). Detections always use TinyRenderer.
    """

    bias: str | BiasConfig = "paper"
    bias_seed: int = 0
    camera_resolution: tuple[int, int] = (1920, 1080)
    pixel_noise_px: float = 0.0
    render_resolution: tuple[int, int] | None = None
    renderer: str = "auto"

    def __post_init__(self) -> None:
        # gym.make passes lists from JSON-like specs; the world wants a tuple.
        object.__setattr__(self, "camera_resolution", check_endoscope_resolution("camera_resolution", self.camera_resolution))
        if isinstance(self.bias, Mapping):  # a BiasConfig's fields, as dataclasses.asdict or a JSON file gives them
            try:
                object.__setattr__(self, "bias", BiasConfig(**self.bias))
            except TypeError as error:
                raise ValueError(f"bias given as a dict must hold BiasConfig's fields ({error})") from None
        if isinstance(self.bias, str):
            check_choice("bias", self.bias, sorted(BIAS_PRESETS))
        elif not isinstance(self.bias, BiasConfig):
            raise ValueError(
                f"bias must be one of {sorted(BIAS_PRESETS)}, a BiasConfig or a dict of its fields, got {type(self.bias).__name__}"
            )
        check_int_fields(type(self).__name__, self, {"bias_seed": (0, 2**31 - 1)})
        check_float_fields(type(self).__name__, self, {"pixel_noise_px": (0.0, MAX_PIXEL_NOISE_PX, False)})
        if self.render_resolution is not None:
            object.__setattr__(self, "render_resolution", check_resolution("render_resolution", self.render_resolution))
        check_choice("renderer", self.renderer, DISPLAY_RENDERERS)


@dataclass(frozen=True)
class ExplorationConfig(EnvConfig):
    """Settings of CalibrationExploration-v0.

    Attributes:
        max_steps: commanded poses per trajectory (the paper: 5,256 samples over 57
            trajectories, about 92 each: 31 pauses x 3 rotations).
    """

    max_steps: int = paper.PHASE1_POSES_PER_TRAJECTORY

    def __post_init__(self) -> None:
        super().__post_init__()
        check_int_fields("ExplorationConfig", self, {"max_steps": (1, 100_000)})


@dataclass(frozen=True)
class GridTouchConfig(EnvConfig):
    """Settings of GridTouch-v0.

    Attributes:
        reward_type: "dense" (minus the goal distance in millimetres) or "sparse" (0 when
            within ``distance_threshold_m``, else -1).
        distance_threshold_m: success radius around the circle centre, metres.
        approach_height_m: how far above the target the tool goes before descending, m.
        correction_noise_m: standard deviation of a person's correction, per axis, metres
            (the paper's Phase II corrections were made by hand).
        contact: how a touch sent under the paper ends (:mod:`dvrk_gym.sim.table.contact`):
            "compliant" (the arm goes on down, stopping short of its command, and the jaws
            slide along the paper, as the authors' records show the real robot did) or
            "rigid" (it stops where the jaws meet the paper).
    """

    reward_type: str = "dense"
    distance_threshold_m: float = 0.001
    approach_height_m: float = 0.008
    correction_noise_m: float = 0.0002
    contact: str = DEFAULT_CONTACT

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice("reward_type", self.reward_type, REWARD_TYPES)
        check_choice("contact", self.contact, tuple(CONTACTS))
        bounds = {
            "distance_threshold_m": (0.0, 0.05, False),
            "approach_height_m": (0.0, 0.05, False),
            "correction_noise_m": (0.0, 0.01, False),
        }
        check_float_fields("GridTouchConfig", self, bounds, units=dict.fromkeys(bounds, "m"))
