"""A progress bar whose clock keeps running while no work ends.

tqdm redraws a bar only when it is updated, so a bar over tasks of minutes each (a sweep's
units, reproduce's calibration) sat at ``0% [00:00<?]`` for minutes, like a hung run.
:func:`running_clock` redraws it from a thread meanwhile: its elapsed time moves.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

from tqdm.auto import tqdm

MIN_REDRAW_S = 1.0
"""The bar is redrawn this often, seconds, or at its ``mininterval`` if longer (10 s when
the command line's output is piped to a file)."""
JOIN_TIMEOUT_S = 5.0
"""How long the block's end waits for the thread, seconds: a Ctrl-C that ends a draw in the
waiting thread leaves tqdm's lock held (tqdm releases it without ``finally``), and the
thread, a daemon, would wait for it for ever. (A non-blocking refresh is no way out:
tqdm's write lock takes its locks one by one and does not say if one failed.)"""


@contextlib.contextmanager
def running_clock(bar: tqdm) -> Iterator[tqdm]:
    """Redraw ``bar`` every ``max(bar.mininterval, MIN_REDRAW_S)`` seconds while in the block.

    A disabled bar is left alone (no thread). The bar must stay open until the block ends.
    """
    if bar.disable:
        yield bar
        return
    interval_s = max(float(bar.mininterval), MIN_REDRAW_S)
    stop = threading.Event()

    def redraw() -> None:
        while not stop.wait(interval_s):
            bar.refresh()  # under the bar's lock, as the waiting thread's updates are

    thread = threading.Thread(target=redraw, name="progress-clock", daemon=True)
    thread.start()
    try:
        yield bar
    finally:
        stop.set()
        thread.join(timeout=JOIN_TIMEOUT_S)
