"""One PyBullet physics server per world, with bodies named by string.

Every world owns its own client (``pybullet_utils.bullet_client``), so any number of
worlds live in one process without seeing each other, and ``close()`` frees the server.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import logging
import os
import sys
import warnings
from collections.abc import Iterator
from typing import Any

import pybullet
from pybullet_utils import bullet_client

from dvrk_gym.sim.physics.meshes import Mesh
from dvrk_gym.utils.checks import check_float

logger = logging.getLogger(__name__)

GRAVITY_M_S2 = 9.81
DEFAULT_TIME_STEP_S = 1.0 / 240.0
MAX_TIME_STEP_S = 0.1
"""The longest physics time step a Physics takes, s (PyBullet's contacts fail long before)."""
_LAYOUTS = itertools.count()  # layout versions, unique across every Physics of the process


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
def quiet_output(stderr: bool = False) -> Iterator[None]:
    """Silence what C code prints to file descriptor 1 (and 2 with ``stderr``); a no-op for a
    stream that cannot be redirected."""
    with contextlib.ExitStack() as stack:
        for fd in (1, 2) if stderr else (1,):
            stack.enter_context(_quiet_fd(fd))
        yield


@contextlib.contextmanager
def _quiet_fd(fd: int) -> Iterator[None]:
    try:
        (sys.stdout if fd == 1 else sys.stderr).flush()
        saved = os.dup(fd)
    except (OSError, ValueError):
        yield
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, fd)
        finally:
            os.close(devnull)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


class Physics:
    """A PyBullet physics server and the named bodies in it.

    Args:
        gui: open the PyBullet GUI (needs a display) instead of a headless server.
        time_step_s: the fixed physics time step, in seconds (in (0, ``MAX_TIME_STEP_S``]).
    """

    def __init__(self, gui: bool = False, time_step_s: float = DEFAULT_TIME_STEP_S) -> None:
        time_step_s = check_float("time_step_s", time_step_s, low=0.0, high=MAX_TIME_STEP_S, low_open=True, unit="s")
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
        with quiet_output():  # the server prints "argv[0]=" on every connection
            self._client: bullet_client.BulletClient | None = _BoundClient(connection_mode=mode)
        self.time_step_s = time_step_s
        self._bodies: dict[str, int] = {}
        self._meshes: dict[str, tuple[Mesh, ...]] = {}
        self._pending_meshes: list[Mesh] = []
        self.layout_version = next(_LAYOUTS)
        """Changes whenever a body is added or removed, or the world is emptied (a display
        mirror rebuilds its copy then); no two layouts of any two Physics share one."""
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

    def mesh_visual(
        self,
        mesh: Mesh,
        rgba: tuple[float, float, float, float],
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
    ) -> int:
        """Create ``mesh`` as a visual shape (frame ``position`` m, ``orientation`` quaternion
        (x, y, z, w) in its link's frame) and return its id.

        The mesh is remembered for the next body :meth:`add` registers, which is the one it
        belongs to: create a body's meshes right before adding it. PyBullet cannot give a
        mesh built from vertices back, and a display mirror needs it (:meth:`meshes`).
        """
        visual = mesh.visual_shape(self.client, rgba, position, orientation)
        self._pending_meshes.append(mesh)
        return visual

    def meshes(self, name: str) -> tuple[Mesh, ...]:
        """The meshes built in code (:meth:`mesh_visual`) of the body ``name``, in creation order."""
        self.body(name)
        return self._meshes[name]

    def add(self, name: str, body_id: int) -> int:
        """Register a body under a unique name and return its id; the meshes made since the
        last body was added (:meth:`mesh_visual`) are this body's."""
        if name in self._bodies:
            raise PhysicsError(f"a body named {name!r} already exists")
        self._bodies[name] = body_id
        self._meshes[name] = tuple(self._pending_meshes)
        self._pending_meshes.clear()
        self.layout_version = next(_LAYOUTS)
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
        del self._meshes[name]
        self.layout_version = next(_LAYOUTS)

    def reset(self) -> None:
        """Remove every body and restore the server's settings (a fresh, empty world)."""
        self.client.resetSimulation()
        self._forget_bodies()
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
            self._forget_bodies()

    def _forget_bodies(self) -> None:
        self._bodies.clear()
        self._meshes.clear()
        self._pending_meshes.clear()
        self.layout_version = next(_LAYOUTS)

    def __del__(self) -> None:
        if hasattr(self, "_client"):  # __init__ may have failed before the server existed
            self.close()
