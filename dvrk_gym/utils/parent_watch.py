"""Worker processes that end when their parent does, however the parent ends.

A pool's workers outlive a parent killed with SIGKILL: nothing tells them, and they go on
running and writing into the run folder. :func:`end_with_parent`, run first in each
worker (a pool's ``initializer``), makes sure they do not:

- on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` has the kernel kill the worker the moment
  its parent dies;
- everywhere, a daemon thread asks :mod:`psutil` every ``poll_s`` whether the parent still
  runs (the same process: its pid and start time) and ends the worker at once if not.

Files the worker was writing are written atomically (:mod:`dvrk_gym.utils.atomic`), so
ending it mid-write loses nothing that was finished.
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys
import threading

import psutil

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
            os._exit(ORPHAN_EXIT_STATUS)


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
