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
    else the import wrote there (a warning, an error's words; also when the import fails).
    Does nothing if it is already imported; imports as usual if standard error is not a file
    descriptor (a notebook, a test's capture) or no temporary file can be made.

    Raises:
        ImportError: pybullet cannot be imported (after its words are passed on).
    """
    if "pybullet" in sys.modules:
        return
    try:
        fd = sys.stderr.fileno()
        captured = tempfile.TemporaryFile()  # noqa: SIM115  (closed by the with below, once the fallback is ruled out)
    except (AttributeError, OSError, ValueError):
        import pybullet  # noqa: F401

        return
    with captured:
        sys.stderr.flush()
        saved = os.dup(fd)
        try:
            os.dup2(captured.fileno(), fd)
            try:
                import pybullet  # noqa: F401
            finally:
                os.dup2(saved, fd)
        finally:
            os.close(saved)
            captured.seek(0)
            for line in captured.read().decode(errors="replace").splitlines():
                if not line.startswith(BANNER_PREFIX):
                    print(line, file=sys.stderr)
