"""Files written whole or not at all: a reader never sees a half-written file.

The content goes to a temporary file in the target's own folder (so the rename stays on one
file system), which then replaces the target with :func:`os.replace`, atomic on POSIX and
Windows.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

__all__ = ["write_atomic", "write_text_atomic"]

_FILE_MODE = 0o644


def write_atomic(path: str | os.PathLike, write: Callable[[Path], object]) -> Path:
    """Call ``write(temporary_path)``, then move the temporary file onto ``path``.

    Args:
        path: the file to write; its folder must exist.
        write: writes the whole content to the path it is given (it keeps ``path``'s suffix).

    Returns:
        ``path`` as a :class:`Path`.
    """
    target = Path(path)
    handle, temporary = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=target.suffix)
    os.close(handle)
    try:
        write(Path(temporary))
        os.chmod(temporary, _FILE_MODE)  # mkstemp makes it private; a result file is for everyone to read
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return target


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`write_atomic`)."""
    return write_atomic(path, lambda temporary: temporary.write_text(text, encoding="utf-8"))
