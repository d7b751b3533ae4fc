"""Worker processes that end when their parent does, however the parent ends, and scratch
folders that do not outlive the process that made them.

A pool's workers outlive a parent killed with SIGKILL: nothing tells them, and they go on
running and writing into the run folder. :func:`end_with_parent`, run first in each
worker (a pool's ``initializer``), makes sure they do not:

- on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` has the kernel kill the worker the moment
  its parent dies;
- everywhere, a daemon thread asks :mod:`psutil` every ``poll_s`` whether the parent still
  runs (the same process: its pid and start time) and ends the worker at once if not.

Files the worker was writing are written atomically (:mod:`dvrk_gym.utils.atomic`), so
ending it mid-write loses nothing that was finished. A worker stopped with SIGTERM deletes
its scratch folders first (:func:`clean_up_on_sigterm`); one ended with SIGKILL cannot, so
a :class:`ScratchFolder` is named for its host and process, and first deletes those of this
host's processes that are gone.
"""

from __future__ import annotations

import ctypes
import logging
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import threading
from pathlib import Path

import psutil

from dvrk_gym.utils.checks import check_file_stem

logger = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1
"""prctl(2)'s option that sets the signal a process gets when its parent dies (Linux)."""
ORPHAN_EXIT_STATUS = 70
"""The exit status of a worker that ended because its parent was gone."""
DEFAULT_POLL_S = 0.5
"""How often the watchdog thread looks for the parent, seconds."""


def _kernel_kills_on_parent_death() -> bool:
    """Ask Linux to SIGKILL this process when its parent dies; False where that is not available."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, 9, 0, 0, 0) == 0  # 9: SIGKILL
    except (OSError, AttributeError):
        return False


def _watch(parent: psutil.Process, poll_s: float) -> None:
    stop = threading.Event()
    while not stop.wait(poll_s):
        if not parent.is_running():  # pid gone, or reused by another process (start time differs)
            remove_own_scratch()
            os._exit(ORPHAN_EXIT_STATUS)


def clean_up_on_sigterm() -> None:
    """Make SIGTERM delete this process's scratch folders, then end it (status 143).

    A local pool's workers are stopped with SIGTERM (Ctrl-C of the command that runs them);
    by default a worker ended at once, and left its unit's folder behind until the next
    sweep on the host deleted it. The folder is deleted from the signal's handler, in the
    main thread, while the work that writes into it waits.
    """

    def end(signum: int, frame: object) -> None:
        remove_own_scratch()
        os._exit(128 + signal.SIGTERM)

    signal.signal(signal.SIGTERM, end)


def end_with_parent(parent_pid: int, poll_s: float = DEFAULT_POLL_S) -> None:
    """Make this process end as soon as process ``parent_pid`` (its parent) ends.

    Args:
        parent_pid: the parent's process id, as the parent saw it (``os.getpid()`` there).
        poll_s: how often the watchdog thread checks, seconds (> 0).
    """
    if not poll_s > 0:
        raise ValueError(f"poll_s must be > 0 seconds, got {poll_s!r}")
    _kernel_kills_on_parent_death()
    try:
        parent = psutil.Process(parent_pid)
    except psutil.NoSuchProcess:
        os._exit(ORPHAN_EXIT_STATUS)  # the parent died before this worker started
    if os.getppid() != parent_pid:  # it died between the start and the prctl above
        os._exit(ORPHAN_EXIT_STATUS)
    threading.Thread(target=_watch, args=(parent, poll_s), name="parent-watch", daemon=True).start()


_LIVE_SCRATCH: set[ScratchFolder] = set()
"""The scratch folders not yet deleted (a forked child holds a copy: each deletes only its maker's)."""


def remove_own_scratch() -> None:
    """Delete the scratch folders this process made and has not deleted (it is ending)."""
    for folder in list(_LIVE_SCRATCH):
        folder.cleanup()


class ScratchFolder:
    """A temporary folder of this process, ``{prefix}{host}_{pid}_...`` in the temporary
    folder; first the folders of ``prefix`` that ended processes on this host left are
    deleted (:func:`remove_orphaned_scratch`).

    :meth:`cleanup` (or leaving it as a context manager) deletes it in the process that made
    it only: a process forked from that one, which holds a copy of this object, leaves it
    alone (a ``TemporaryDirectory``'s finalizer in the child deleted the parent's folder).

    Args:
        prefix: names the folder's owner, e.g. ``"dvrk_gym_sweep_"`` (a plain name).
    """

    def __init__(self, prefix: str) -> None:
        remove_orphaned_scratch(prefix)
        self._pid = os.getpid()
        self.name = tempfile.mkdtemp(prefix=f"{prefix}{host_label()}_{self._pid}_")
        """The folder's path."""
        _LIVE_SCRATCH.add(self)

    def cleanup(self) -> None:
        """Delete the folder and what it holds, if this is the process that made it."""
        if os.getpid() == self._pid:
            shutil.rmtree(self.name, ignore_errors=True)
            _LIVE_SCRATCH.discard(self)

    def __enter__(self) -> str:
        return self.name

    def __exit__(self, *exc_info: object) -> None:
        self.cleanup()


def host_label() -> str:
    """This machine's name as a scratch folder holds it: letters, digits and ``-``."""
    return re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname()) or "host"


def orphaned_scratch(prefix: str, root: Path | None = None) -> list[Path]:
    """The folders ``{prefix}{host}_{pid}_*`` in ``root`` (default: the temporary folder) made
    on this host by a process ``pid`` that no longer runs, and that belong to this user.

    A folder of another host (a temporary folder shared between machines) is not one, and
    neither is one whose pid now names another process (until that one ends too).
    """
    mine = check_file_stem("a scratch prefix (a plain name)", prefix) + host_label() + "_"
    found = []
    for folder in Path(root or tempfile.gettempdir()).glob(f"{mine}*_*"):
        pid = folder.name[len(mine) :].split("_", 1)[0]
        try:
            if not pid.isdigit() or folder.is_symlink() or not folder.is_dir() or folder.stat().st_uid != os.getuid():
                continue
        except OSError:  # gone meanwhile
            continue
        if not psutil.pid_exists(int(pid)):
            found.append(folder)
    return found


def remove_orphaned_scratch(prefix: str, root: Path | None = None) -> list[Path]:
    """Delete the folders :func:`orphaned_scratch` finds; the deleted folders."""
    removed = orphaned_scratch(prefix, root)
    for folder in removed:
        shutil.rmtree(folder, ignore_errors=True)
        logger.info("deleted %s, left by a process that ended", folder)
    return removed
