"""A sweep's units on a Dask cluster (``dask.distributed``): the only module that imports dask.

Start a scheduler and workers wherever they may run (``dask scheduler`` on one machine,
``dask worker tcp://HOST:8786 --nthreads 1`` on each of the others, or a job queue's
``dask-jobqueue``), with dvrk-gym installed at the same version on every worker; then
``dvrk-gym sweep --scheduler tcp://HOST:8786``. Workers need no shared disk: each unit
sends its numbers back and the process that runs the sweep writes them. Give each worker
one thread (``--nthreads 1``): a unit runs with one torch thread and PyBullet's own loop,
so more threads per worker only make units share a core.

Install with ``pip install "dvrk-gym[dask]"``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from distributed import Client, Future, as_completed
from distributed.comm import get_address_host_port, parse_address

from dvrk_gym.sweep.executors import Outcome, outcome_of

logger = logging.getLogger(__name__)

T = TypeVar("T")

CONNECT_TIMEOUT_S = 10.0
"""How long to try to reach a scheduler before giving up, seconds."""


class DaskExecutor:
    """Runs items on the workers of a running Dask scheduler.

    Args:
        address: the scheduler's address, ``tcp://host:port`` (``LocalCluster.scheduler_address``
            in tests).
        connect_timeout_s: how long to try to reach it, seconds.

    Raises:
        ValueError: the address is malformed, or the scheduler could not be reached in time.
    """

    def __init__(self, address: str, connect_timeout_s: float = CONNECT_TIMEOUT_S) -> None:
        try:
            if parse_address(address)[0] != "inproc":  # a malformed address fails here, before a client exists
                get_address_host_port(address)
        except ValueError as error:
            raise ValueError(f"the scheduler address {address!r} is malformed ({error}); expected such as tcp://host:8786") from None
        try:
            self.client = Client(address, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError) as error:
            raise ValueError(
                f"cannot reach a Dask scheduler at {address!r} within {connect_timeout_s:g} s ({type(error).__name__}: {error}); "
                "expected the address of a running scheduler, such as tcp://host:8786"
            ) from None
        try:
            workers = self.client.scheduler_info(n_workers=-1)["workers"]  # all of them (some versions list five by default)
        except TypeError:  # older versions: no n_workers, and every worker listed
            workers = self.client.scheduler_info()["workers"]
        threads = sum(int(worker.get("nthreads", 1)) for worker in workers.values())
        self.description = f"Dask scheduler {address} ({len(workers)} workers, {threads} threads)"
        if not workers:
            logger.warning("the Dask scheduler at %s has no workers yet: units wait until one joins", address)

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        futures: list[Future] = self.client.map(function, list(items), pure=False)
        item_of = {future.key: item for future, item in zip(futures, items)}
        try:
            for future in as_completed(futures, loop=self.client.loop):  # this client: it is not the default one
                yield outcome_of(item_of[future.key], future.result)
        finally:
            self.client.cancel([future for future in futures if not future.done()])

    def close(self) -> None:
        self.client.close()

    def __enter__(self) -> DaskExecutor:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
