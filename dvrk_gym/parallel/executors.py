"""Where work runs: the executor interface, local process pools, and this process.

An executor runs module-level functions somewhere and hands back
:class:`concurrent.futures.Future` objects (:meth:`Executor.submit`), so that code using
it waits with :func:`concurrent.futures.wait` or ``as_completed`` whatever runs the work.
On top of that, :meth:`Executor.map_unordered` runs one function over items and yields
each outcome as it finishes, a failure being an outcome too, so the other items go on.
Three implementations run the same functions with the same results:
:class:`LocalExecutor` (spawned local processes, the default), :class:`InlineExecutor`
(this process, one call at a time) and :class:`~dvrk_gym.parallel.dask_executor.DaskExecutor`
(a ``dask.distributed`` cluster; that module is the only one that imports dask).
"""

from __future__ import annotations

import concurrent.futures as cf
import functools
import multiprocessing
import numbers
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

from dvrk_gym.utils.parent_watch import clean_up_on_sigterm, end_with_parent

T = TypeVar("T")

MAX_LOCAL_WORKERS = 1024
"""The most processes a local pool starts (each imports torch and PyBullet: some 300 MB)."""
STOP_GRACE_S = 3.0
"""How long :meth:`LocalExecutor.stop` lets a worker delete its scratch folders after SIGTERM
before it kills it, seconds (the handler runs once a long C call returns)."""


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

    @property
    def failure(self) -> str:
        """What went wrong, for people: ``"ValueError: ..."``; a call cancelled with no
        words (a Dask scheduler lost mid-run) says so. Empty if nothing went wrong."""
        if self.error is None:
            return ""
        words = str(self.error) or (
            "cancelled before it finished (on Dask: the scheduler, or the connection to it, was lost)"
            if isinstance(self.error, cf.CancelledError)  # Dask's FutureCancelledError among them
            else "(no message)"
        )
        return f"{type(self.error).__name__}: {words}"


class Executor(Protocol):
    """Runs functions somewhere; used as a context manager (``close`` on exit)."""

    description: str
    """Where the work runs, for people: ``"2 local processes"``."""

    def submit(self, function: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        """Start ``function(*args, **kwargs)``; its future holds the result or the error.

        ``function`` must be a module-level function (a worker imports it by name) and the
        arguments picklable.
        """
        ...

    def capacity(self) -> int:
        """How many calls run at once now (at least 1): a caller that keeps its own queue
        submits no more than this, so that it can still choose what starts next."""
        ...

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        """Run ``function(item)`` for every item; yield each outcome as it finishes.

        Closing the iterator early cancels the items not started (and stops those running).
        """
        ...

    def stop(self) -> None:
        """Stop now: cancel the calls waiting and end the ones running where the executor
        can (a local pool's workers are ended; the executor can be used again)."""
        ...

    def close(self) -> None:
        """Release the workers, once what was submitted has finished."""
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


class FuturesExecutor:
    """What the executors share: :meth:`map_unordered` on top of :meth:`submit`, and the
    context manager. A subclass sets ``description`` and implements ``submit``,
    ``capacity``, ``stop`` and ``close``."""

    description = "an executor"

    def submit(self, function: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        raise NotImplementedError

    def capacity(self) -> int:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        """``function`` of each item, as each finishes. A finished call's future is let go
        before its outcome is yielded: on Dask a held future keeps its result on its worker,
        and a worker lost later took those results with it and the cluster ran them again."""
        futures = {self.submit(function, item): item for item in items}
        try:
            for future in cf.as_completed(futures):
                outcome = outcome_of(futures.pop(future), future.result)
                del future
                yield outcome
        finally:
            self._abandon(futures)

    def _abandon(self, futures: Iterable[cf.Future]) -> None:
        """Cancel the calls not finished when :meth:`map_unordered` is left; if some are
        running (left early: an error, Ctrl-C), :meth:`stop`, rather than wait for them."""
        unfinished = [future for future in futures if not future.done()]
        for future in unfinished:
            future.cancel()
        if not all(future.cancelled() for future in unfinished):
            self.stop()

    def __enter__(self) -> FuturesExecutor:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _start_worker(parent_pid: int, setup: Callable[[], None] | None) -> None:
    """A local worker's start: end with the parent, delete its scratch folders when stopped,
    give tqdm a thread lock, then the executor's ``setup``.

    tqdm's default lock holds a multiprocessing semaphore, made by the first bar (even a
    disabled one); a worker stopped by :meth:`LocalExecutor.stop` (Ctrl-C) cannot unlink it,
    and the resource tracker warned of "leaked semaphore objects" as the command ended. A
    spawned worker shares no lock with its parent anyway, so a thread lock loses nothing.
    """
    end_with_parent(parent_pid)
    clean_up_on_sigterm()  # stopped (Ctrl-C), it deletes its scratch folders first
    import threading

    import tqdm

    tqdm.tqdm.set_lock(threading.RLock())
    if setup is not None:
        setup()


class LocalExecutor(FuturesExecutor):
    """A pool of ``workers`` spawned processes on this machine (``concurrent.futures``).

    Spawned, not forked, so no torch or PyBullet state is copied into a worker. Each
    worker ends with the process that made the pool, even when that one is killed
    (:func:`~dvrk_gym.utils.parent_watch.end_with_parent`). The pool starts with the first
    :meth:`submit`; after :meth:`stop`, or once a worker has died (every call then running
    fails with ``BrokenProcessPool``), the next ``submit`` starts a new one.

    Args:
        workers: processes running calls side by side (at least 1).
        setup: called once in each worker as it starts (a module-level function; the command
            line's imports PyBullet there without its banner, which would cut into the
            progress bar), or None.

    Raises:
        ValueError: ``workers`` below 1.
    """

    def __init__(self, workers: int = 2, *, setup: Callable[[], None] | None = None) -> None:
        if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or not 1 <= workers <= MAX_LOCAL_WORKERS:
            raise ValueError(f"workers is {workers!r}; expected an int in [1, {MAX_LOCAL_WORKERS}]")
        self.workers: int = int(workers)
        self.description = f"{workers} local process{'es' if workers > 1 else ''}"
        self.setup: Callable[[], None] | None = setup
        self._pool: cf.ProcessPoolExecutor | None = None

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=functools.partial(_start_worker, os.getpid(), self.setup),
        )

    def submit(self, function: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        if self._pool is None:
            self._pool = self._new_pool()
        try:
            return self._pool.submit(function, *args, **kwargs)
        except BrokenProcessPool:  # a worker died earlier: its calls failed, the pool takes no more
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = self._new_pool()
            return self._pool.submit(function, *args, **kwargs)

    def capacity(self) -> int:
        return self.workers

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        """As :meth:`Executor.map_unordered`, ``workers`` items at a time. A worker that dies (killed,
        out of memory) breaks the pool, and every call in it fails with ``BrokenProcessPool``:
        those items run again one at a time in a new pool (one that was running alone is not
        run again), so only the one that kills its worker fails, and the items not yet
        started go on once they are done."""
        waiting: list[T] = list(items)
        running: dict[cf.Future, T] = {}
        suspects: list[T] = []  # items whose call failed with the pool's death: each runs again alone
        try:
            while waiting or running or suspects:
                if suspects and not running:  # alone in a new pool: a BrokenProcessPool now is the item's own
                    item = suspects.pop(0)
                    running[self.submit(function, item)] = item
                    cf.wait(running)
                    future, item = running.popitem()  # (in ``running`` while it runs: Ctrl-C stops it)
                    yield outcome_of(item, future.result)
                    continue
                while waiting and len(running) < self.workers and not suspects:
                    item = waiting.pop(0)
                    running[self.submit(function, item)] = item
                done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                alone = len(running) == 1  # a pool broken under one item alone: that item killed its worker
                for future in done:
                    item = running.pop(future)
                    outcome = outcome_of(item, future.result)
                    if isinstance(outcome.error, BrokenProcessPool) and not alone:
                        suspects.append(item)
                    else:
                        yield outcome
        finally:
            self._abandon(running)

    def stop(self) -> None:
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
            process.join(timeout=STOP_GRACE_S)
            if process.is_alive():  # its handler waits for a long C call to return: not for ever
                process.kill()
                process.join(timeout=STOP_GRACE_S)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class InlineExecutor(FuturesExecutor):
    """Runs each call here, in this process, when it is submitted (one at a time).

    For one worker: no process to start, and a call's own progress bars and logging show
    as they happen. The returned future is already done.
    """

    description = "this process"

    def submit(self, function: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        future: cf.Future = cf.Future()
        future.set_running_or_notify_cancel()
        try:
            future.set_result(function(*args, **kwargs))
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as error:  # noqa: BLE001  (handed to the caller through the future, as a pool does)
            future.set_exception(error)
        return future

    def map_unordered(self, function: Callable[[T], Any], items: Sequence[T]) -> Iterator[Outcome[T]]:
        for item in items:  # one after another, each outcome handed on before the next call starts
            yield outcome_of(item, functools.partial(function, item))

    def capacity(self) -> int:
        return 1

    def stop(self) -> None:
        """Nothing runs in the background here."""

    def close(self) -> None:
        """Nothing to release."""


def local_executor(workers: int, *, setup: Callable[[], None] | None = None) -> FuturesExecutor:
    """The executor for ``workers`` local workers: :class:`InlineExecutor` for 1, else
    :class:`LocalExecutor` (whose workers call ``setup`` as they start)."""
    return InlineExecutor() if workers == 1 else LocalExecutor(workers, setup=setup)
