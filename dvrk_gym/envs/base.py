"""The base every dvrk_gym environment is built on: one world, one config, strict inputs.

A subclass has a frozen config dataclass extending :class:`EnvConfig`, and an ``__init__``
whose keyword arguments are that config's fields, written out (so ``help()``, editors and
``inspect.signature`` show them) and documented by the config's docstring (appended to the
``__init__`` docstring for ``help()``). It names its action components (``action_names``)
and implements ``_reset_episode`` and ``_step_episode`` (and ``_check_options``, which
checks its reset options before anything changes: a refused reset leaves the env as it
was). The base owns the world, the action checks, seeding, state restoration and
rendering, so no environment repeats them. A closed env refuses every call of this API
(``reset``, ``step``, ``render``, ``carried_state``, ``restore_carried_state``) but ``close``.
"""

from __future__ import annotations

import difflib
import functools
import inspect
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, Generic, TypeVar

import gymnasium as gym
import numpy as np
from gymnasium.error import ClosedEnvironmentError, ResetNeeded

from dvrk_gym.envs.configs import EnvConfig
from dvrk_gym.sim.endoscope.display import EndoscopeDisplay
from dvrk_gym.sim.robot.kinematics import JOINT_NAMES
from dvrk_gym.sim.world import DvrkWorld, WorldConfig

ConfigT = TypeVar("ConfigT", bound=EnvConfig)


def config_arguments(arguments: dict[str, Any]) -> dict[str, Any]:
    """An env constructor's keyword arguments, from its ``locals()``: all but ``self``, ``render_mode`` and ``__class__``."""
    return {name: value for name, value in arguments.items() if name not in ("self", "render_mode", "__class__")}


def config_docs(config_class: type) -> str:
    """The ``Attributes:`` entries of ``config_class`` and its bases, as one indented block."""
    blocks = []
    for klass in reversed(config_class.__mro__):
        doc = inspect.getdoc(klass) or ""
        if "Attributes:" in doc and klass is not object:
            blocks.append(doc.split("Attributes:", 1)[1].strip("\n"))
    return "\n".join(blocks)


def checking_keywords(init: Callable[..., None]) -> Callable[..., None]:
    """``init`` (an env's ``__init__``) that first refuses a keyword it does not take.

    The ``TypeError`` names the env's class (the subclass's, for one that inherits ``init``),
    the keyword, the nearest one it takes and all the ones it takes
    (Python's own names only the bad keyword), before any world is built; ``gym.make``
    passes it on. ``inspect.signature`` and ``help()`` still show ``init``'s own signature.
    A constructor with ``**kwargs`` is returned as it is.
    """
    parameters = inspect.signature(init).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return init
    allowed = sorted(name for name, p in parameters.items() if name != "self" and p.kind is not inspect.Parameter.VAR_POSITIONAL)

    @functools.wraps(init)
    def checked(self: Any, *args: Any, **kwargs: Any) -> None:
        for name in kwargs:
            if name not in allowed:
                close = difflib.get_close_matches(name, allowed, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                listed = ", ".join(allowed)
                raise TypeError(f"{type(self).__name__} got an unexpected keyword argument {name!r}{hint}; its keywords are: {listed}")
        init(self, *args, **kwargs)

    return checked


def check_action(action: Any, space: gym.spaces.Box, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Validate an action against a Box space.

    Returns:
        (the action clipped into the space as float64, boolean mask of clipped elements).

    Raises:
        ValueError: not real numbers (complex, bool, text), wrong shape, or an element that is
            NaN or infinite (named in the message).
    """
    try:
        raw = np.asarray(action)
    except ValueError as error:  # a ragged nesting
        raise ValueError(
            f"action must be an array of shape {space.shape} ({', '.join(names)}), got {type(action).__name__} ({error})"
        ) from None
    if raw.shape != space.shape:
        raise ValueError(f"action must have shape {space.shape} ({', '.join(names)}), got {raw.shape}")
    if raw.dtype.kind not in "fiu":  # complex, bool, strings and objects are not coerced
        raise ValueError(f"action must hold real numbers ({', '.join(names)}), got dtype {raw.dtype} ({action!r})")
    array = raw.astype(np.float64)
    for i, value in enumerate(array):
        if not np.isfinite(value):
            raise ValueError(f"action[{i}] ({names[i]}) is {value}; expected a finite value in [{space.low[i]:.4g}, {space.high[i]:.4g}]")
    clipped = np.clip(array, space.low.astype(np.float64), space.high.astype(np.float64))
    return clipped, clipped != array


def relax_option(options: dict[str, Any], seeded: bool) -> bool:
    """The ``"relax"`` reset option: True relaxes the cables at the episode's start; False
    keeps the arm's cable history from the episodes before.

    The default is True for a seeded reset, so that a seed alone fixes an episode (as
    Gymnasium's contract and ``check_env`` want), and False otherwise.

    Raises:
        ValueError: the option is not a bool.
    """
    relax = options.get("relax", seeded)
    if not isinstance(relax, (bool, np.bool_)):
        raise ValueError(f"option 'relax' must be True or False, got {relax!r}")
    return bool(relax)


class DvrkEnv(gym.Env, Generic[ConfigT]):
    """Shared machinery of the dvrk_gym environments.

    Args:
        config: the environment's settings (a subclass builds it from its keyword arguments).
        render_mode: None (default), "rgb_array" (the left endoscope image) or "human"
            (the PyBullet GUI; needs a display).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 4}
    config_class: ClassVar[type[EnvConfig]] = EnvConfig
    action_names: tuple[str, ...] = ()
    action_space: gym.spaces.Box  # every dvrk_gym env acts through a Box
    option_names: ClassVar[tuple[str, ...]] = ()
    carried_attributes: ClassVar[tuple[str, ...]] = ()
    """Attributes of a subclass (JSON values) that one episode leaves to the next reset;
    part of :meth:`carried_state`."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Make the subclass's ``__init__`` refuse unknown keywords clearly (:func:`checking_keywords`)
        and append the config's field docs to its docstring, for ``help()``."""
        super().__init_subclass__(**kwargs)
        if "__init__" in cls.__dict__:
            cls.__init__ = checking_keywords(cls.__dict__["__init__"])  # type: ignore[method-assign]
            fields = "\n".join("    " + line if line else line for line in config_docs(cls.config_class).splitlines())
            cls.__init__.__doc__ = (
                f"{inspect.cleandoc(cls.__init__.__doc__ or '')}\n\nKeyword arguments ({cls.config_class.__name__}'s fields):\n{fields}\n"
            )

    def __init__(self, config: ConfigT, render_mode: str | None = None) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if not isinstance(config, self.config_class):
            raise TypeError(f"{type(self).__name__} needs a {self.config_class.__name__}, got {type(config).__name__}")
        self.render_mode = render_mode
        self.config: ConfigT = config
        self.world = DvrkWorld(
            WorldConfig(
                camera_resolution=self.config.camera_resolution,
                bias=self.config.bias,
                bias_seed=self.config.bias_seed,
                gui=render_mode == "human",
                pixel_noise_px=self.config.pixel_noise_px,
            )
        )
        self._initial_physics_state = self.world.physics.client.saveState()
        # A new arm has no cable history: its first episode starts with relaxed cables
        # wherever the episode starts (building the world put them at rest at HOME_JOINTS,
        # which is not where any episode starts).
        cable = self.world.cable
        cable.set_state(np.full(cable.get_state().shape, np.nan))
        self._needs_reset = True
        self._closed = False
        self._seeded_reset = False  # whether the reset under way was given a seed
        self._display: EndoscopeDisplay | None = None  # made at the first image rendered

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Start an episode (Gymnasium's ``reset``). The seed and the options are checked
        before anything changes: a refused reset leaves the env as it was (its episode, if
        one was under way, can go on).

        Raises:
            TypeError: ``seed`` is not an int, or ``options`` not a dict.
            ValueError: a negative seed, an unknown option or a bad option value.
            gymnasium.error.ClosedEnvironmentError: the env was closed.
        """
        self._refuse_if_closed("reset")
        if seed is not None:
            if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
                raise TypeError(f"seed must be None or an int, got {seed!r}")
            if seed < 0:
                raise ValueError(f"seed must be a non-negative int, got {seed}")
            seed = int(seed)
        if options is not None and not isinstance(options, Mapping):
            raise TypeError(f"options must be None or a dict of reset options {list(self.option_names)}, got {_describe(options)}")
        options = dict(options or {})
        unknown = sorted(set(options) - set(self.option_names), key=str)
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; valid options: {list(self.option_names)}")
        self._check_options(options, seeded=seed is not None)
        super().reset(seed=seed)
        self._restore_initial_state()
        self._seeded_reset = seed is not None
        observation, info = self._reset_episode(options)
        self._needs_reset = False
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self._refuse_if_closed("step")
        if self._needs_reset:
            raise ResetNeeded("call reset() before step(): the episode has not started or has ended")
        clipped, clamped = check_action(action, self.action_space, self.action_names)
        observation, reward, terminated, truncated, info = self._step_episode(clipped, clamped)
        if terminated or truncated:
            self._needs_reset = True
        return observation, reward, terminated, truncated, info

    def render(self) -> np.ndarray | list[Any] | None:
        self._refuse_if_closed("render")
        if self.render_mode == "rgb_array":
            return self._render_frame()
        return None  # "human": the PyBullet GUI shows the world live; None: nothing to draw

    def _render_frame(self) -> np.ndarray:
        """The left endoscope image to show, (h, w, 3) uint8 RGB at ``render_resolution``."""
        if self._display is None:
            self._display = EndoscopeDisplay(self.world.camera, self.config.render_resolution, self.config.renderer)
        return self._display.image(self.world.physics, "left")

    def close(self) -> None:
        display = getattr(self, "_display", None)  # __init__ may have failed before it was set
        if display is not None:
            display.close()
        if hasattr(self, "world"):
            self.world.close()
        self._closed = True
        super().close()

    def __del__(self) -> None:
        """An env dropped without ``close()`` frees its physics server now: a Debridement
        table and its world refer to each other, and would wait for the garbage collector
        (a loop of 30 envs made and dropped held up to 15 servers). A closed env has nothing to
        free; at interpreter exit the modules may be gone (even ``contextlib``), hence a plain ``try``."""
        if getattr(self, "_closed", False):
            return
        try:  # noqa: SIM105  (contextlib may be gone at exit)
            self.close()
        except Exception:  # whatever is gone at exit: nothing left to free
            pass

    def _refuse_if_closed(self, call: str) -> None:
        if getattr(self, "_closed", False):
            raise ClosedEnvironmentError(
                f"{type(self).__name__}.{call}(): the env is closed (its physics server is gone); make another env"
            )

    # ------------------------------------------------------------------ what carries between episodes
    def carried_state(self) -> dict[str, Any]:
        """What this env carries into its next reset, as JSON values.

        A reset restores the physics and starts the episode from this state alone (and the
        reset's own seed and options): the env's random generator, the cable model's
        history (:meth:`~dvrk_gym.sim.robot.cables.CableModel.get_state`; NaN entries, a
        fresh arm's, as None), the commanded joints (rad / m) and the subclass's
        :attr:`carried_attributes`. So an env built afresh, given this state by
        :meth:`restore_carried_state` and reset with the same seed and options, starts the
        same episode bit for bit (a resumed training relies on it).
        """
        self._refuse_if_closed("carried_state")
        world = self.world
        cable = world.cable.get_state()
        return {
            "np_random": self.np_random.bit_generator.state,
            "cable": [[None if np.isnan(x) else float(x) for x in row] for row in cable],
            "q_cmd": [float(x) for x in world.q_cmd],
            "attributes": {name: getattr(self, name) for name in self.carried_attributes},
        }

    def restore_carried_state(self, state: dict[str, Any]) -> None:
        """Take up a :meth:`carried_state` (of an env made with the same settings); reset next.

        Raises:
            ValueError: ``state`` is not one :meth:`carried_state` returns.
        """
        self._refuse_if_closed("restore_carried_state")
        expected = {"np_random", "cable", "q_cmd", "attributes"}
        if not isinstance(state, dict) or set(state) != expected:
            raise ValueError(f"a carried state is a dict with keys {sorted(expected)}, got {_describe(state)}")
        attributes = state["attributes"]
        if not isinstance(attributes, dict) or set(attributes) != set(self.carried_attributes):
            raise ValueError(f"carried attributes must be {sorted(self.carried_attributes)}, got {_describe(attributes)}")
        try:
            cable = np.array([[np.nan if x is None else float(x) for x in row] for row in state["cable"]], dtype=float)
            q_cmd = np.array([float(x) for x in state["q_cmd"]], dtype=float)
        except (TypeError, ValueError, OverflowError) as error:
            raise ValueError(f"a carried state's 'cable' and 'q_cmd' must hold numbers ({error})") from None
        if q_cmd.shape != self.world.q_cmd.shape or not np.isfinite(q_cmd).all():
            raise ValueError(f"carried 'q_cmd' must be {self.world.q_cmd.shape[0]} finite joint values, got {state['q_cmd']!r}")
        generator = np.random.Generator(np.random.PCG64())
        try:
            generator.bit_generator.state = state["np_random"]
        except (TypeError, ValueError, KeyError, OverflowError) as error:
            raise ValueError(f"carried 'np_random' is not a PCG64 generator's state ({error})") from None
        self._check_carried_attributes(attributes)
        self.world.cable.set_state(cable)  # checks the shape and the values
        self.world.q_cmd = q_cmd
        self.np_random = generator
        for name, value in attributes.items():
            setattr(self, name, value)
        self._needs_reset = True

    # ------------------------------------------------------------------ no copies
    def _refuse_copy(self, what: str) -> TypeError:
        return TypeError(
            f"{type(self).__name__} cannot be {what}: it owns a PyBullet physics server, which a copy would share "
            f"(two envs stepping one world). Make another env instead: gym.make(env.spec.id, **env.spec.kwargs), "
            f"or {type(self).__name__}(**dataclasses.asdict(env.unwrapped.config)), and reset it with the same seed"
        )

    def __copy__(self) -> DvrkEnv:
        raise self._refuse_copy("copied")

    def __deepcopy__(self, memo: dict[int, Any]) -> DvrkEnv:
        raise self._refuse_copy("deep-copied")

    def __reduce_ex__(self, protocol: Any) -> Any:
        raise self._refuse_copy("pickled")

    # ------------------------------------------------------------------ helpers for subclasses
    def _restore_initial_state(self) -> None:
        """Put the physics back as it was when the env was made (an env that rebuilds its
        world on reset overrides this)."""
        self.world.restore_physics(self._initial_physics_state)

    def _check_options(self, options: dict[str, Any], seeded: bool) -> None:
        """Check the reset options' values (their names are checked already) without changing
        anything; ``seeded``: the reset was given a seed.

        Raises:
            ValueError: a bad option value.
        """
        if "relax" in options:
            relax_option(options, seeded)

    def _check_carried_attributes(self, attributes: dict[str, Any]) -> None:
        """Check a carried state's :attr:`carried_attributes` before they are taken up (a
        subclass with any overrides this).

        Raises:
            ValueError: an attribute value this env could not have carried.
        """

    def _reset_episode(self, options: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
        raise NotImplementedError

    def _step_episode(self, action: np.ndarray, clamped: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        raise NotImplementedError

    def _clamped_names(self, clamped: np.ndarray, joints_clamped: np.ndarray | None = None) -> list[str]:
        """Names of the clamped action elements and joints, for ``info["clamped"]``."""
        names = [self.action_names[i] for i in np.flatnonzero(clamped)]
        if joints_clamped is not None:
            names += [f"joint:{JOINT_NAMES[i]}" for i in np.flatnonzero(joints_clamped)]
        return names


def _describe(value: Any) -> str:
    """A short description of a value that is not what was expected, for error messages."""
    if isinstance(value, dict):
        return f"a dict with keys {sorted(map(str, value))}"
    return f"{type(value).__name__}"
