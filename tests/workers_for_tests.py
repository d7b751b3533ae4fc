"""Task functions for the executor tests: module-level (a worker process imports them by
name) and light (only the standard library), so a spawned worker starts in a moment."""

import os
import time
from pathlib import Path


def record(name: str, log: str, needs_seen: tuple[str, ...] = ()) -> dict:
    """Append ``name`` to the log, after checking that every task it needs logged itself first."""
    seen = Path(log).read_text().split() if Path(log).exists() else []
    missing = [need for need in needs_seen if need not in seen]
    if missing:
        raise AssertionError(f"{name} ran before {missing}")
    with open(log, "a") as handle:
        handle.write(name + "\n")
    return {"name": name, "pid": os.getpid()}


def die_once(flag: str) -> str:
    """Kill this (worker) process with SIGKILL the first time; return normally once ``flag`` exists."""
    if not Path(flag).exists():
        Path(flag).write_text("died once")
        os.kill(os.getpid(), 9)
    return "survived"


def square_or_die(n: int) -> int:
    """``n * n`` after a moment (so that calls overlap); a negative ``n`` kills its worker with SIGKILL."""
    time.sleep(0.3)
    if n < 0:
        os.kill(os.getpid(), 9)
    return n * n


def import_pybullet() -> bool:
    """Import PyBullet in this (worker) process; whether it was imported before."""
    import sys

    before = "pybullet" in sys.modules
    import pybullet  # noqa: F401

    return before


def disabled_bar(n: int) -> int:
    """``n``, after a disabled tqdm bar (the first bar makes tqdm's lock)."""
    import tqdm

    for _ in tqdm.tqdm(range(1), disable=True):
        pass
    return n


def sleep_for(seconds: float) -> dict:
    """Sleep ``seconds`` (a long task's stand-in) and say how long."""
    time.sleep(seconds)
    return {"slept_s": seconds}


def scratch_then_wait(seconds: float) -> str:
    """Make a sweep's scratch folder, then wait ``seconds`` in it (a unit stopped midway)."""
    from dvrk_gym.utils.parent_watch import ScratchFolder

    with ScratchFolder("dvrk_gym_sweep_") as folder:
        (Path(folder) / "phase1.npz").write_bytes(b"x" * 1000)
        time.sleep(seconds)
        return folder


def deaf_to_sigterm(seconds: float, began: str) -> str:
    """Ignore SIGTERM, write the file ``began``, then wait ``seconds`` (as a worker deep in a
    long C call is, for a while)."""
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    Path(began).write_text("deaf")
    time.sleep(seconds)
    return "finished"
