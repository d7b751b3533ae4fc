"""A display copy of a physics world, drawn by PyBullet's EGL renderer (OpenGL without a window).

PyBullet's software renderer (TinyRenderer) takes 0.75 s of CPU for a 1920 x 1080 frame of
the workspace; its EGL plugin (Mesa's llvmpipe on a machine without a GPU) 0.17 s, in four
tiles (``benchmarks/bench_render.py``). The plugin cannot simply be loaded into a world's
own client:

* once loaded into a client it draws every ``getCameraImage`` of that client, whatever
  ``renderer=`` says, so the perception images (TinyRenderer's, which the detections and
  hence every calibration number rest on) would change;
* it draws only the bodies created after it was loaded;
* it does not draw visual shapes built from vertices in code (the printed circles, the
  fragments, the tool's shaft): it reads meshes from files only.

So :class:`EglMirror` is a second client, with the plugin loaded before any body, holding
a copy of each visual shape (meshes built in code, and boxes, written as OBJ files to a
temporary folder while the copy is built), moved to the world's poses before each frame.
The world's own client is never touched, so its images stay bit for bit what they were.
The plugin's EGL state is shared beyond its client, so all mirrors of a thread share one
such client (:class:`_SharedEglClient`), each rebuilding its copy there when another's was
built since.

When the plugin cannot be loaded it calls ``exit()`` inside the process (without libEGL,
for one), so :func:`~dvrk_gym.sim.physics.egl_probe.egl_usable` first tries it in a child process.
"""

from __future__ import annotations

import atexit
import logging
import os
import threading
import weakref
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pybullet
from pybullet_utils import bullet_client

from dvrk_gym.sim.physics.client import Physics, quiet_output
from dvrk_gym.sim.physics.egl_probe import EGL_PLUGIN_MODULE, egl_plugin_path, egl_usable
from dvrk_gym.sim.physics.meshes import Mesh, box
from dvrk_gym.utils.atomic import atomic_write_text
from dvrk_gym.utils.parent_watch import ScratchFolder

logger = logging.getLogger(__name__)

EGL_MAX_IMAGE_PX = (1024, 768)
"""The largest image (width, height) the EGL plugin draws as asked: it draws into a surface of
this size, and stretches anything larger from it. Draw larger images in tiles."""
TINY_LIGHT_DIRECTION = (-50.0, 30.0, 100.0)
"""Where TinyRenderer's light comes from (world frame, z up; PyBullet's default)."""
LIGHT_DISTANCE_M = 1.0e4
"""How far away the EGL renderer's light is put (its shader lights by direction). The plugin
draws a shadow map from the light every frame, 4096 texels over 20 m, 1 m to 300 m in
front of it: a millimetre scene would shadow itself in 5 mm blotches. A light this far
away leaves the whole scene beyond the shadow map's depth range: all of it is lit."""
EGL_LIGHT_POSITION = [LIGHT_DISTANCE_M * v / float(np.linalg.norm(TINY_LIGHT_DIRECTION)) for v in TINY_LIGHT_DIRECTION]
SCRATCH_PREFIX = "dvrk_gym_display_"
"""How the renderer's scratch folders of meshes begin (:class:`~dvrk_gym.utils.parent_watch.ScratchFolder`)."""


class RendererUnavailable(RuntimeError):
    """PyBullet's EGL renderer cannot run here (no plugin, no libEGL, no EGL device)."""


def egl_forked() -> bool:
    """Whether this process was forked from one that had started PyBullet's EGL renderer
    (:attr:`_SharedEglClient.started_in_pid`): its EGL state does not work here."""
    return _SharedEglClient.started_in_pid not in (None, os.getpid())


def refuse_if_forked() -> None:
    """Raise RendererUnavailable (saying what to do) in a process forked after EGL started."""
    if egl_forked():
        raise RendererUnavailable(
            f"PyBullet's EGL renderer was started in process {_SharedEglClient.started_in_pid} before this process "
            "was forked from it, and its state does not survive a fork (drawing with it here would hang or crash); "
            "start an async vector env's workers with 'spawn' or 'forkserver' "
            "(gym.make_vec(..., vector_kwargs={'context': 'spawn'})), or render with renderer='tiny'"
        )


@dataclass(frozen=True)
class _Copy:
    """One mirrored visual shape: the world's body and link index it is on, and the mirror's body drawing it."""

    body: int
    link: int
    mirror_body: int


class EglMirror:
    """A copy of a world's visual shapes in a client of its own, drawn by the EGL renderer.

    Each copy sits at its world pose; the light comes from TinyRenderer's direction
    (:data:`LIGHT_DISTANCE_M`), so the two renderers light the scene alike.

    Args:
        plugin_path: the EGL plugin's file (default: pybullet's own, :func:`egl_plugin_path`).

    Raises:
        RendererUnavailable: the plugin is missing or fails to start (one line says why).
    """

    def __init__(self, plugin_path: str | None = None) -> None:
        path = egl_plugin_path() if plugin_path is None else plugin_path
        if path is None:
            raise RendererUnavailable(f"this pybullet has no EGL renderer plugin (module {EGL_PLUGIN_MODULE!r} not found)")
        refuse_if_forked()
        failure = egl_usable(path)
        if failure is not None:
            raise RendererUnavailable(f"PyBullet's EGL renderer ({path}) does not run here: {failure}")
        self._shared: _SharedEglClient | None = _SharedEglClient.acquire(path)
        # Gives the client back when closed, collected, or at exit (while the streams still work).
        self._release = weakref.finalize(self, _release, self._shared, os.getpid())
        self._layout: int | None = None  # the layout_version of the Physics copied
        self._copies: list[_Copy] = []
        self._written: list[str] = []  # the OBJ files written for the rebuild under way
        self._names: dict[int, str] = {}  # their names, one string object each

    @property
    def client(self) -> bullet_client.BulletClient:
        """The client the mirror draws in (its thread's one EGL client); raises RendererUnavailable once closed."""
        if self._shared is None:
            raise RendererUnavailable("this EGL mirror has been closed")
        refuse_if_forked()  # a mirror made before the fork: its client is the parent's
        return self._shared.client

    @property
    def copies(self) -> tuple[tuple[int, int, int], ...]:
        """(world body id, link index (-1: base), mirror body id) of every mirrored visual shape."""
        return tuple((c.body, c.link, c.mirror_body) for c in self._copies)

    def sync(self, physics: Physics) -> None:
        """Make the copy match ``physics``: rebuilt if bodies came or went, every shape moved to its link's pose."""
        if self._layout != physics.layout_version or self.client_holds_another_copy:
            self._rebuild(physics)
        source, mirror = physics.client, self.client
        for copy in self._copies:
            position, orientation = link_frame(source, copy.body, copy.link)
            mirror.resetBasePositionAndOrientation(copy.mirror_body, position, orientation)

    def image(self, width: int, height: int, view_matrix: list[float], projection_matrix: list[float]) -> np.ndarray:
        """Draw the copy as it was last synced: (height, width, 3) uint8 RGB, row 0 at the top.

        Args:
            width, height: image size, pixels, at most :data:`EGL_MAX_IMAGE_PX`.
            view_matrix, projection_matrix: OpenGL matrices, column-major lists of 16 floats.
        """
        if not (0 < width <= EGL_MAX_IMAGE_PX[0] and 0 < height <= EGL_MAX_IMAGE_PX[1]):
            raise ValueError(
                f"the EGL renderer draws images of 1x1 to {EGL_MAX_IMAGE_PX[0]}x{EGL_MAX_IMAGE_PX[1]} pixels, got {width}x{height}; "
                "draw a larger one in tiles"
            )
        with quiet_output():  # the plugin prints the GL vendor on some frames
            result = self.client.getCameraImage(
                width,
                height,
                viewMatrix=view_matrix,
                projectionMatrix=projection_matrix,
                renderer=pybullet.ER_BULLET_HARDWARE_OPENGL,
                shadow=0,
                lightDirection=EGL_LIGHT_POSITION,
                flags=pybullet.ER_NO_SEGMENTATION_MASK,
            )
        # (OpenCV drops the alpha channel some 25x faster than a strided numpy copy)
        return cv2.cvtColor(np.asarray(result[2], dtype=np.uint8).reshape(height, width, 4), cv2.COLOR_RGBA2RGB)

    @property
    def client_holds_another_copy(self) -> bool:
        """Whether another mirror's copy was built in the shared client since this one's (the next sync rebuilds)."""
        return self._shared is not None and self._shared.holder is not self._release

    def close(self) -> None:
        """Give the shared client back (the last mirror to close unloads the plugin and disconnects
        it); safe to call more than once. (Each rebuild deletes its mesh files once read.)"""
        self._release()
        self._shared = None
        self._copies = []

    # ------------------------------------------------------------------ building the copy
    def _rebuild(self, physics: Physics) -> None:
        mirror = self.client
        assert self._shared is not None  # self.client has checked
        self._shared.holder = None  # the copy there is gone: should this rebuild fail, every mirror rebuilds
        with quiet_output():
            mirror.resetSimulation()
        self._copies = []
        for name in physics.body_names:
            body = physics.body(name)
            by_link: dict[int, list[tuple]] = {}
            for entry in physics.client.getVisualShapeData(body):
                by_link.setdefault(entry[1], []).append(entry)
            meshes = list(physics.meshes(name))
            built_in_code = sum(1 for entries in by_link.values() for e in entries if _from_vertices(e))
            if built_in_code != len(meshes):
                raise RendererUnavailable(
                    f"body {name!r} has {built_in_code} visual meshes built from vertices but {len(meshes)} were made "
                    "through Physics.mesh_visual; make a body's meshes with it, right before Physics.add"
                )
            for link in sorted(by_link):
                for entry in by_link[link]:  # one body per shape: shape arrays leak their file names
                    visual = self._visual_shape(entry, meshes)
                    self._copies.append(_Copy(body, link, mirror.createMultiBody(0.0, -1, visual)))
        self._layout = physics.layout_version
        self._shared.holder = self._release
        for path in self._written:  # read by now
            Path(path).unlink()
        self._written = []

    def _visual_shape(self, entry: tuple, meshes: list[Mesh]) -> int:
        """The mirror's copy of one ``getVisualShapeData`` entry (``meshes``: the body's
        code-built meshes still to place, taken in order)."""
        kind, dims, file_name = entry[2], list(entry[3]), entry[4]
        if _from_vertices(entry):
            file_name = self._obj_file(meshes.pop(0))
        elif kind == pybullet.GEOM_BOX:  # the plugin lights the two triangles of its own box faces apart
            kind, file_name, dims = pybullet.GEOM_MESH, self._obj_file(box(tuple(dims))), [1.0, 1.0, 1.0]
        elif kind not in (pybullet.GEOM_SPHERE, pybullet.GEOM_CYLINDER, pybullet.GEOM_CAPSULE, pybullet.GEOM_MESH):
            raise RendererUnavailable(f"the EGL mirror cannot copy visual shapes of PyBullet geometry type {kind}")
        round_ = kind in (pybullet.GEOM_CYLINDER, pybullet.GEOM_CAPSULE)
        with quiet_output():
            return self.client.createVisualShape(
                kind,
                radius=dims[1] if round_ else dims[0],
                length=dims[0] if round_ else 0.0,
                fileName=file_name if isinstance(file_name, str) else file_name.decode(),
                meshScale=dims if kind == pybullet.GEOM_MESH else [1.0, 1.0, 1.0],
                rgbaColor=list(entry[7]),
                visualFramePosition=list(entry[5]),
                visualFrameOrientation=list(entry[6]),
            )

    def _obj_file(self, mesh: Mesh) -> str:
        """The path of a new OBJ file holding ``mesh``, for this rebuild.

        Files are numbered in the order of the rebuild, in the process's one folder
        (:func:`_mesh_folder`) under the shared client's slot, so every rebuild of every mirror
        uses the same names: pybullet keeps every file name it is given for the life of the
        process, and names it has seen cost nothing more (a folder of each mirror's own cost
        0.14 MB for each env that rendered, for good). The loader's cache is off, so a file is read when
        its shape is made and can then be replaced.
        """
        if self._shared is None:
            raise RendererUnavailable("this EGL mirror has been closed")
        number = len(self._written)
        path = self._names.setdefault(number, str(Path(_mesh_folder()) / f"client{self._shared.slot}_mesh{number}.obj"))
        atomic_write_text(path, mesh.obj_text())
        self._written.append(path)
        return path


class _SharedEglClient:
    """A thread's one client with the EGL plugin loaded, shared by the thread's :class:`EglMirror` s.

    The plugin's EGL state is shared beyond its client: a second client's plugin in the same
    thread shares it, so unloading it (or disconnecting its client) while another was drawing
    crashed the process at that one's next frame, and resetting one client's world blanked
    the others' frames. So a thread's mirrors draw in one client: each rebuilds its copy
    there when another mirror's copy was built since (:attr:`holder`; two envs drawn in turn
    rebuild at every frame, about 2.5 times a frame's time), and the last mirror to go
    unloads the plugin. The EGL context is current in the thread that loaded the plugin
    only, so each thread has its own client.
    """

    _by_key: dict[tuple[str, int], _SharedEglClient] = {}
    _lock = threading.Lock()
    started_in_pid: int | None = None
    """The process that first loaded the plugin. Its EGL state (Mesa's, which stays after the
    plugin is unloaded) is copied into a process forked from it and does not work there: a
    forked child reusing the client crashed, and one starting its own hung in its first frame."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.key = (path, threading.get_ident())
        with quiet_output(stderr=True):  # the server and the plugin print their start-up to the C streams
            self.client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
            self.plugin = self.client.loadPlugin(path, "_eglRendererPlugin")
        if self.plugin < 0:
            self.client.disconnect()
            raise RendererUnavailable(f"PyBullet could not load its EGL renderer from {path}")
        if _SharedEglClient.started_in_pid is None:
            _SharedEglClient.started_in_pid = os.getpid()
        # A loaded OBJ file is cached for the life of the process unless this is off, and
        # fragments bring new meshes at every reset.
        self.client.setPhysicsEngineParameter(enableFileCaching=0)
        self.users = 0
        self.slot = 0
        """Its number among the clients alive at once (one a thread), which names its mesh files."""
        self.holder: object | None = None  # the release handle of the mirror whose copy the client holds

    @classmethod
    def acquire(cls, path: str) -> _SharedEglClient:
        """This thread's shared client for the plugin at ``path``, made on first use; one more user of it."""
        with cls._lock:
            shared = cls._by_key.get((path, threading.get_ident()))
            if shared is None:
                shared = cls(path)
                taken = {other.slot for other in cls._by_key.values()}
                shared.slot = min(set(range(len(taken) + 1)) - taken)  # the lowest free: a new thread's client reuses names
                cls._by_key[shared.key] = shared
            shared.users += 1
            return shared

    def give_back(self) -> None:
        """One user fewer; the last unloads the plugin and disconnects the client."""
        with self._lock:
            self.users -= 1
            if self.users > 0:
                return
            self._by_key.pop(self.key, None)
        with quiet_output():  # the plugin says goodbye on the C streams
            try:
                self.client.unloadPlugin(self.plugin)
                self.client.disconnect()
            except pybullet.error:
                logger.debug("the EGL mirror's server was already disconnected")


def _release(shared: _SharedEglClient, pid: int) -> None:
    """Give a mirror's share of the EGL client back; nothing in a process forked from the one
    (``pid``) that made the mirror: the client is that one's."""
    if os.getpid() == pid:
        shared.give_back()


_MESH_FOLDERS: dict[int, ScratchFolder] = {}
"""This process's folder of mesh files (by process id: a forked child does not use its parent's)."""
_MESH_FOLDER_LOCK = threading.Lock()


def _mesh_folder() -> str:
    """The folder the EGL mirrors of this process write their mesh files into: made on first
    use, deleted when the process exits (one a killed process left is deleted by the next
    process that makes one, :class:`~dvrk_gym.utils.parent_watch.ScratchFolder`)."""
    with _MESH_FOLDER_LOCK:
        folder = _MESH_FOLDERS.get(os.getpid())
        if folder is None:
            folder = _MESH_FOLDERS[os.getpid()] = ScratchFolder(SCRATCH_PREFIX)
            atexit.register(folder.cleanup)
        return folder.name


def _from_vertices(entry: tuple) -> bool:
    """Whether a ``getVisualShapeData`` entry is a mesh built from vertices (no file name)."""
    return entry[2] == pybullet.GEOM_MESH and not entry[4]


def link_frame(client: bullet_client.BulletClient, body: int, link: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The world pose of a link's frame (the frame its visual shapes are placed in): position
    (m) and quaternion (x, y, z, w). Link -1 is the base, whose frame is its centre of mass
    less the local inertial offset."""
    if link >= 0:
        state = client.getLinkState(body, link, computeForwardKinematics=True)
        return state[4], state[5]
    com_position, com_orientation = client.getBasePositionAndOrientation(body)
    inertial_position, inertial_orientation = client.getDynamicsInfo(body, -1)[3:5]
    to_frame = client.invertTransform(inertial_position, inertial_orientation)
    return client.multiplyTransforms(com_position, com_orientation, *to_frame)
