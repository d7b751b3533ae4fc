"""torch's intra-op thread count for a block of code (the small networks here train fastest on one)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``n`` torch intra-op threads, then restore the previous number.

    One thread is what the RL baselines, ``dvrk-gym reproduce``'s tasks and ``dvrk-gym sweep``'s
    units train with, and the calibration network always (:mod:`dvrk_gym.calibration.models.dnn`):
    on 2 shared cores, two threads made a 256 x 256 update 12 times slower, and a fixed count
    gives the same numbers whatever the machine's cores (not whatever its CPU: MKL picks its
    kernels by instruction set; README: the network's figures depend on the machine's arithmetic).

    The count is torch's setting for the process (a thread that starts later takes it up), so
    blocks in Python threads that run at once can restore each other's count in the wrong
    order; the package's executors run one task per process (``dvrk_gym.parallel``, Dask
    workers with one thread each).
    """
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(previous)
