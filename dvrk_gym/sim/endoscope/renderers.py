"""The names of what may draw the images shown to people (``env.render()``).

Plain names only, without PyBullet, so that the envs' settings (:mod:`dvrk_gym.envs.configs`)
can check them when ``dvrk_gym`` is imported; :mod:`dvrk_gym.sim.endoscope.display` says
what each does.
"""

from __future__ import annotations

__all__ = ["DISPLAY_RENDERERS"]

DISPLAY_RENDERERS = ("auto", "egl", "tiny")
"""What a display may be asked to draw with: "auto" (EGL when it runs, else TinyRenderer),
"egl" (an error if it cannot run) or "tiny" (PyBullet's TinyRenderer)."""
