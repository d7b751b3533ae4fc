"""Where a sweep's units run: the interface, and a pool of local processes (the default).

An executor runs a module-level function on each of a list of items and yields each
outcome as it finishes, in any order (:meth:`Executor.map_unordered`). A failure is an
outcome too, so the other items go on. Two implementations run the same functions:
:class:`LocalExecutor` (here: ``concurrent.futures`` with spawned processes) and
:class:`~dvrk_gym.sweep.dask_executor.DaskExecutor` (a ``dask.distributed`` cluster; that
module is the only one that imports dask).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

T = TypeVar("T")


@dataclass(frozen=True)
class Outcome(Generic[T]):
    """How one item went.

    Attributes:
        item: the item, as given.
        result: the function's return value (None if it raised).
        error: what it raised, or None.
    """

    item: T
    result: Any = None
    error: BaseException | None = None


class Executor(Protocol):
    """Runs a function on items, somewhere; used as a context manager (``close`` on exit)."""

    description: str
    """Where the work runs, for people: ``"2 local processes"``."""

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        """Run ``function(item)`` for every item; yield each outcome as it finishes.

        ``function`` must be a module-level function (its process imports it by name) and
        the items picklable. Closing the iterator early cancels the items not started.
        """
        ...

    def close(self) -> None:
        """Release the workers."""
        ...

    def __enter__(self) -> Executor: ...

    def __exit__(self, *exc_info: object) -> None: ...


def outcome_of(item: T, result: Callable[[], Any]) -> Outcome[T]:
    """The outcome of a finished future: ``result()`` returns its value or raises its error."""
    try:
        return Outcome(item, result(), None)
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as error:  # noqa: BLE001  (a cancelled future raises a BaseException in some libraries)
        return Outcome(item, None, error)


class LocalExecutor:
    """A pool of ``workers`` spawned processes on this machine (``concurrent.futures``).

    Spawned, not forked, so no torch or PyBullet state is copied into a worker. The pool
    starts with the first :meth:`map_unordered` and is kept until :meth:`close`.

    Args:
        workers: processes running items side by side (at least 1).

    Raises:
        ValueError: ``workers`` below 1.
    """

    def __init__(self, workers: int = 2) -> None:
        if workers < 1:
            raise ValueError(f"workers is {workers}; expected at least 1")
        self.workers = int(workers)
        self.description = f"{self.workers} local process{'es' if self.workers > 1 else ''}"
        self._pool: ProcessPoolExecutor | None = None

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"))
        futures: dict[Future, T] = {self._pool.submit(function, item): item for item in items}
        try:
            for future in as_completed(futures):
                yield outcome_of(futures[future], future.result)
        finally:
            unfinished = [future for future in futures if not future.done()]
            for future in unfinished:
                future.cancel()
            if any(future.running() for future in unfinished):
                self._stop_workers()  # left early (an error, Ctrl-C): do not wait for running items

    def _stop_workers(self) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if hasattr(pool, "terminate_workers"):  # Python >= 3.14
            pool.terminate_workers()
            return
        # Before 3.14 the pool names its worker processes only in ``_processes``: those, and
        # no other child of this process, are stopped.
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join(timeout=5)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> LocalExecutor:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
