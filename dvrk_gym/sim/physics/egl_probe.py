"""Whether PyBullet's EGL renderer plugin runs here, tried in a child process.

When the plugin cannot be loaded it calls ``exit()`` inside the process (without libEGL, for
one), so :func:`egl_usable` tries it in a child first; :class:`~dvrk_gym.sim.physics.mirror.EglMirror`
asks before it loads the plugin.
"""

from __future__ import annotations

import functools
import importlib.util
import subprocess
import sys

EGL_PLUGIN_MODULE = "eglRenderer"
"""The module pybullet's wheel ships its EGL renderer plugin as."""
PROBE_TIMEOUT_S = 60.0
"""How long the child process that tries the EGL plugin may take, seconds."""
_PROBE_SENTINEL = "dvrk_gym-egl-probe-ok"
# Loads the plugin, draws a red box filling a 32 x 24 frame, and says so if the centre is red.
_PROBE_CODE = f"""
import sys, numpy, pybullet
from pybullet_utils import bullet_client
c = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
if c.loadPlugin(sys.argv[1], "_eglRendererPlugin") < 0:
    sys.exit(3)
box = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=[1, 1, 0.1], rgbaColor=[1, 0, 0, 1])
c.createMultiBody(0, baseVisualShapeIndex=box)
view = pybullet.computeViewMatrix([0, 0, 2], [0, 0, 0], [0, 1, 0])
proj = pybullet.computeProjectionMatrixFOV(40, 32 / 24, 0.1, 10)
rgba = c.getCameraImage(32, 24, view, proj, renderer=pybullet.ER_BULLET_HARDWARE_OPENGL)[2]
r, g, b = (int(v) for v in numpy.reshape(numpy.asarray(rgba, dtype=numpy.uint8), (24, 32, 4))[12, 16, :3])
c.disconnect()
print("{_PROBE_SENTINEL}" if r > 200 and g < 60 and b < 60 else f"centre pixel {{(r, g, b)}}", flush=True)
"""


def egl_plugin_path() -> str | None:
    """Where pybullet's EGL renderer plugin is, or None if this pybullet has none."""
    spec = importlib.util.find_spec(EGL_PLUGIN_MODULE)
    return None if spec is None else spec.origin


@functools.lru_cache(maxsize=8)
def egl_usable(plugin_path: str) -> str | None:
    """Try the EGL plugin at ``plugin_path`` in a child process (once per path and process).

    Returns:
        None if it loaded and drew a frame; otherwise why not, in one line.
    """
    try:
        done = subprocess.run(
            [sys.executable, "-c", _PROBE_CODE, plugin_path],
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return f"trying it took more than {PROBE_TIMEOUT_S:g} s"
    if _PROBE_SENTINEL in done.stdout:
        return None
    said = [line.strip() for line in (done.stderr + done.stdout).splitlines() if line.strip() and "build time" not in line]
    return f"trying it exited with status {done.returncode}" + (f" ({said[-1]})" if said else "")
