"""One PyBullet physics server per world, with bodies named by string.

Every world owns its own client (``pybullet_utils.bullet_client``), so any number of
worlds live in one process without seeing each other, and ``close()`` frees the server.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import sys
import warnings
from collections.abc import Iterator
from typing import Any

import pybullet
from pybullet_utils import bullet_client

logger = logging.getLogger(__name__)

GRAVITY_M_S2 = 9.81
DEFAULT_TIME_STEP_S = 1.0 / 240.0


class _BoundClient(bullet_client.BulletClient):
    """A ``BulletClient`` that binds each pybullet function to its server once.

    ``BulletClient`` makes a new ``functools.partial`` at every attribute access (a
    physics step of the debridement table makes about twenty); here the first one is
    kept on the instance, where later look-ups find it without ``__getattr__``. The calls
    are the same. Disconnecting forgets them, so none outlives its server (whose id
    PyBullet may give to the next one).
    """

    def __getattr__(self, name: str) -> Any:
        if name == "disconnect":
            for bound in [key for key, value in vars(self).items() if isinstance(value, functools.partial)]:
                del self.__dict__[bound]
            return super().__getattr__(name)
        attribute = super().__getattr__(name)
        if isinstance(attribute, functools.partial):
            self.__dict__[name] = attribute
        return attribute


class PhysicsError(RuntimeError):
    """The physics server is closed, or a body name is unknown."""


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence what C code prints to file descriptor 1 (a no-op where it cannot be redirected)."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):
        yield
        return
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class Physics:
    """A PyBullet physics server and the named bodies in it.

    Args:
        gui: open the PyBullet GUI (needs a display) instead of a headless server.
        time_step_s: the fixed physics time step, in seconds.
    """

    def __init__(self, gui: bool = False, time_step_s: float = DEFAULT_TIME_STEP_S) -> None:
        if gui and not os.environ.get("DISPLAY"):
            # Gymnasium's env checker makes every advertised render mode, headless too: run
            # the same physics without a window, and say so, rather than fail.
            warnings.warn(
                "render_mode='human' opens the PyBullet GUI, which needs a display, and DISPLAY is not set: "
                "the simulation runs without a window (use render_mode='rgb_array' for images)",
                RuntimeWarning,
                stacklevel=2,
            )
            gui = False
        mode = pybullet.GUI if gui else pybullet.DIRECT
        with _quiet_stdout():  # the server prints "argv[0]=" on every connection
            self._client: bullet_client.BulletClient | None = _BoundClient(connection_mode=mode)
        self.time_step_s = float(time_step_s)
        self._bodies: dict[str, int] = {}
        self._configure()

    def _configure(self) -> None:
        self.client.setGravity(0.0, 0.0, -GRAVITY_M_S2)
        self.client.setTimeStep(self.time_step_s)
        # Deterministic contact solving: a fixed number of iterations, no random shuffling.
        self.client.setPhysicsEngineParameter(numSolverIterations=50, deterministicOverlappingPairs=1)

    @property
    def client(self) -> bullet_client.BulletClient:
        """The PyBullet client; raises PhysicsError once closed."""
        if self._client is None:
            raise PhysicsError("this physics server has been closed")
        return self._client

    @property
    def is_open(self) -> bool:
        """Whether the server is still running."""
        return self._client is not None

    def add(self, name: str, body_id: int) -> int:
        """Register a body under a unique name and return its id."""
        if name in self._bodies:
            raise PhysicsError(f"a body named {name!r} already exists")
        self._bodies[name] = body_id
        return body_id

    def body(self, name: str) -> int:
        """The PyBullet id of the body called ``name``."""
        try:
            return self._bodies[name]
        except KeyError:
            raise PhysicsError(f"no body named {name!r}; bodies are {sorted(self._bodies)}") from None

    @property
    def body_names(self) -> tuple[str, ...]:
        """The names of all bodies, in creation order."""
        return tuple(self._bodies)

    def remove(self, name: str) -> None:
        """Remove a body from the world."""
        self.client.removeBody(self.body(name))
        del self._bodies[name]

    def reset(self) -> None:
        """Remove every body and restore the server's settings (a fresh, empty world)."""
        self.client.resetSimulation()
        self._bodies.clear()
        self._configure()

    def step(self, n: int = 1) -> None:
        """Advance the physics by ``n`` fixed time steps."""
        for _ in range(n):
            self.client.stepSimulation()

    def close(self) -> None:
        """Disconnect the server; safe to call more than once."""
        if self._client is not None:
            try:
                self._client.disconnect()
            except pybullet.error:  # already gone (e.g. the GUI window was closed)
                logger.debug("physics server was already disconnected")
            self._client = None
            self._bodies.clear()

    def __del__(self) -> None:
        if hasattr(self, "_client"):  # __init__ may have failed before the server existed
            self.close()
