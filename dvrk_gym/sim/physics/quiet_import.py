"""Import PyBullet without its build-time banner.

``import pybullet`` prints ``pybullet build time: ...`` from C onto the process's standard
error, so a command-line error that follows the import is two lines. The command line calls
:func:`import_pybullet_quietly` once, before anything else imports PyBullet; every later
``import pybullet`` finds the module loaded and prints nothing. Library users see PyBullet
as it is.
"""

from __future__ import annotations

import os
import sys
import tempfile

BANNER_PREFIX = "pybullet build time"
"""How PyBullet's import banner begins."""


def import_pybullet_quietly() -> None:
    """Import ``pybullet``, dropping its banner from standard error and passing on anything
    else the import wrote there (a warning, an error's words). Does nothing if it is already
    imported, or if standard error is not a file descriptor (it then imports as usual)."""
    if "pybullet" in sys.modules:
        return
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # a replaced sys.stderr (a notebook, a test's capture)
        import pybullet  # noqa: F401

        return
    sys.stderr.flush()
    saved = os.dup(fd)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), fd)
        try:
            import pybullet  # noqa: F401
        finally:
            os.dup2(saved, fd)
            os.close(saved)
        captured.seek(0)
        text = captured.read().decode(errors="replace")
    for line in text.splitlines():
        if not line.startswith(BANNER_PREFIX):
            print(line, file=sys.stderr)
