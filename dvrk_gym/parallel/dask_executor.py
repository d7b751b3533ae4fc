"""Work on a Dask cluster (``dask.distributed``): the only module that imports dask.

Start a scheduler and workers wherever they may run (``dask scheduler`` on one machine,
``dask worker tcp://HOST:8786 --nthreads 1`` on each of the others, or a job queue's
``dask-jobqueue``), with dvrk-gym installed at the same version on every worker (the
workers are asked at connect, and each call checks first, that they run the same dvrk_gym
source as the process that sends the work, and are named if not: results of two
simulators are never mixed); then
``dvrk-gym sweep --scheduler tcp://HOST:8786`` or ``dvrk-gym reproduce --scheduler ...``.
A sweep's units need no shared disk (each sends its numbers back and the process that runs
the sweep writes them); a reproduction's tasks write their models, tables and figures
into the run folder, so its ``--out`` must be on a disk every worker sees at the same
path. Give each worker one thread (``--nthreads 1``): a call runs with one torch thread
and PyBullet's own loop, so more threads per worker only make calls share a core.

Install with ``pip install -e ".[dask]"`` in a checkout (the extra ``dask``).
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from distributed import Client, get_worker
from distributed.comm import get_address_host_port, parse_address

from dvrk_gym.parallel.executors import FuturesExecutor
from dvrk_gym.utils.checks import check_float
from dvrk_gym.utils.source_fingerprint import SHORT_DIGEST_CHARS, source_fingerprint

logger = logging.getLogger(__name__)

T = TypeVar("T")

CONNECT_TIMEOUT_S = 10.0
"""How long to try to reach a scheduler before giving up, seconds."""


CONNECT_MARGIN_S = 5.0
"""How much longer than its timeout a connection may take before it is given up, seconds."""


def _within(seconds: float, function: Callable[[], T], *, name: str, timeout_message: str, late: Callable[[T], None] | None = None) -> T:
    """``function()`` run in a daemon thread named ``name`` and waited for ``seconds`` at most:
    its value, or what it raised. ``Client(...)`` and ``Client.run`` have no time limit that
    holds however the other end behaves, hence the thread.

    Raises:
        TimeoutError: ``timeout_message``, when it has not returned in time; a value it
            returns later is handed to ``late`` (a client made late is closed).
        BaseException: what ``function`` raised.
    """
    made: dict[str, Any] = {}
    lock = threading.Lock()

    def call() -> None:
        try:
            value = function()
        except BaseException as error:  # noqa: BLE001  (handed to the caller)
            made["error"] = error
            return
        with lock:
            if made.get("given_up"):
                if late is not None:
                    late(value)
            else:
                made["value"] = value

    thread = threading.Thread(target=call, name=name, daemon=True)
    thread.start()
    try:
        thread.join(seconds)
    finally:  # given up in time, or interrupted (Ctrl-C) while waiting
        with lock:
            made.setdefault("given_up", "value" not in made)
    if "value" in made:
        return made["value"]
    if "error" in made:
        raise made["error"]
    raise TimeoutError(timeout_message)


def _connect(address: str, timeout_s: float) -> Client:
    """A client of the scheduler at ``address``, within ``timeout_s`` plus :data:`CONNECT_MARGIN_S`
    seconds however the other end behaves: a port that takes the connection but speaks
    another protocol (a scheduler's dashboard) never answers Dask's handshake, and
    ``Client(address, timeout=...)`` waited for it for ever. A client made after it was given
    up is closed.

    Raises:
        TimeoutError: nothing answered as a scheduler in time.
        Exception: what ``Client`` raised.
    """
    return _within(
        timeout_s + CONNECT_MARGIN_S,
        lambda: Client(address, timeout=timeout_s, set_as_default=False),
        name="dask-connect",
        timeout_message="what answered there is no Dask scheduler (a dashboard's port, say)",
        late=lambda client: client.close(),
    )


class WorkerSourceError(RuntimeError):
    """A Dask worker runs other dvrk_gym source than the process that sent it a call."""


@dataclass(frozen=True)
class SameSourceCall:
    """``function``, called on a worker only if it runs the dvrk_gym source whose
    :func:`~dvrk_gym.utils.source_fingerprint.source_fingerprint` is ``sha256``.

    Raises:
        WorkerSourceError: the worker's source differs (another commit, or edited files).
    """

    function: Callable[..., Any]
    sha256: str

    @property
    def __name__(self) -> str:
        """The function's: Dask names each task by it (``run_unit-<id>``, not this wrapper's repr)."""
        return str(getattr(self.function, "__name__", type(self).__name__))

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        found = source_fingerprint()
        if found.sha256 != self.sha256:
            raise WorkerSourceError(
                f"the Dask worker {_worker_name()} runs {found.short()}, the process that sent the work source "
                f"sha256 {self.sha256[:SHORT_DIGEST_CHARS]}: install the same commit of dvrk-gym on every worker"
            )
        return self.function(*args, **kwargs)


def _worker_name() -> str:
    """This Dask worker's address and host (several workers may share a host), for messages."""
    try:
        return f"{get_worker().address} on {socket.gethostname()}"
    except ValueError:  # not on a worker (a call run here)
        return f"on {socket.gethostname()}"


def worker_source_sha256() -> str:
    """The dvrk_gym source a worker runs (the full SHA-256): asked of every worker at connect."""
    return source_fingerprint().sha256


def _ask_workers(client: Client, timeout_s: float) -> dict[str, Any] | None:
    """Each worker's answer to :func:`worker_source_sha256` (a string, or the error it raised),
    or None if they did not all answer within ``timeout_s`` seconds (a worker stopped or cut
    off: ``Client.run`` waits for every worker, without a time limit of its own)."""
    try:
        answers = _within(
            timeout_s,
            lambda: client.run(worker_source_sha256, on_error="return"),
            name="dask-source-check",
            timeout_message=f"the workers did not all answer within {timeout_s:g} s",
        )
    except Exception:  # noqa: BLE001  (not in time, or the scheduler lost meanwhile: unanswered, as a hung worker)
        return None
    return dict(answers) or None


def _check_workers_source(client: Client, sha256: str, timeout_s: float) -> None:
    """Refuse a cluster whose workers run other dvrk_gym source than ``sha256``, or none.

    Each call checks its worker too (:class:`SameSourceCall`), but a worker that refuses its
    calls in a moment is given the next ones at once: one such worker failed 9 units of a
    sweep of 10. Asked here, it is named before any work is sent. Workers that do not answer
    within ``timeout_s`` seconds, or whose connection fails, are left to the check of each
    call, with a warning (a worker that joins later is checked by each call too).

    Raises:
        ValueError: naming each worker whose source differs or that cannot import dvrk_gym.
    """
    if not client.nthreads():
        return  # no worker yet: each call checks the one that runs it
    answers = _ask_workers(client, timeout_s)
    if answers is None:
        logger.warning("could not ask every Dask worker within %g s which dvrk_gym it runs; each call still checks its own", timeout_s)
        return
    unreachable = sorted(worker for worker, answer in answers.items() if isinstance(answer, OSError))  # lost or cut off
    if unreachable:
        logger.warning("Dask workers %s could not be asked which dvrk_gym they run; each call still checks its own", unreachable)
    others = {worker: answer for worker, answer in answers.items() if worker not in unreachable and answer != sha256}
    if not others:
        return
    described = "; ".join(
        f"{worker}: source sha256 {answer[:SHORT_DIGEST_CHARS]}"
        if isinstance(answer, str)
        else f"{worker}: cannot say which it runs ({answer})"
        for worker, answer in sorted(others.items())
    )
    raise ValueError(
        f"{len(others)} of {len(answers)} Dask workers do not run this dvrk_gym source (sha256 {sha256[:SHORT_DIGEST_CHARS]}), "
        f"so their results would mix two simulators: {described}. Install the same commit of dvrk-gym on every worker, "
        "or stop those workers"
    )


class DaskExecutor(FuturesExecutor):
    """Runs calls on the workers of a running Dask scheduler.

    Futures come from the client's ``concurrent.futures`` view (``Client.get_executor``):
    cancelling one cancels its task on the cluster. Calls are never merged as the same
    (``pure=False``), and each runs only on a worker with this process's dvrk_gym source
    (:class:`SameSourceCall`).

    Args:
        address: the scheduler's address, ``tcp://host:port`` (``LocalCluster.scheduler_address``
            in tests).
        connect_timeout_s: how long to try to reach it, seconds.

    Raises:
        ValueError: the address is malformed, the scheduler could not be reached in time,
            or a worker runs other dvrk_gym source (or none).
    """

    def __init__(self, address: str, connect_timeout_s: float = CONNECT_TIMEOUT_S) -> None:
        connect_timeout_s = check_float("connect_timeout_s", connect_timeout_s, low=0.0, high=3600.0, low_open=True, unit="s")
        if not isinstance(address, str):
            raise ValueError(f"the scheduler address must be a string such as tcp://host:8786, got {address!r}")
        try:
            protocol = parse_address(address)[0]
            if protocol != "inproc":  # a malformed address fails here, before a client exists
                get_address_host_port(address)
        except (ValueError, TypeError) as error:
            raise ValueError(f"the scheduler address {address!r} is malformed ({error}); expected such as tcp://host:8786") from None
        if protocol in ("tls", "wss"):  # these need certificates no option here takes
            raise ValueError(f"the scheduler address {address!r} uses {protocol}://, which needs TLS certificates; give a tcp:// address")
        try:
            self.client = _connect(address, connect_timeout_s)
        except Exception as error:  # whatever answered is not a scheduler (a dashboard's HTTP, garbage read as a huge array)
            # Bytes of another protocol, read as the length of Dask's first message, asked for exbibytes.
            reason = (
                "what answered does not speak Dask's protocol" if isinstance(error, MemoryError) else f"{type(error).__name__}: {error}"
            )
            raise ValueError(
                f"cannot reach a Dask scheduler at {address!r} within {connect_timeout_s:g} s ({reason}); "
                "expected the address of a running scheduler, such as tcp://host:8786"
            ) from None
        self._source = source_fingerprint().sha256
        try:
            _check_workers_source(self.client, self._source, connect_timeout_s)
        except BaseException:
            self.client.close()
            raise
        self._executor = self.client.get_executor(pure=False)
        threads = self._threads()
        self.description = f"Dask scheduler {address} ({len(threads)} workers, {sum(threads.values())} threads)"
        if not threads:
            logger.warning("the Dask scheduler at %s has no workers yet: work waits until one joins", address)

    def _threads(self) -> dict[str, int]:
        """Each worker's threads, as the scheduler knows them now."""
        return {str(worker): int(n) for worker, n in self.client.nthreads().items()}

    def submit(self, function: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        return self._executor.submit(SameSourceCall(function, self._source), *args, **kwargs)

    def capacity(self) -> int:
        """The threads of the workers the scheduler has now (at least 1, so work waits for a worker)."""
        return max(1, sum(self._threads().values()))

    def stop(self) -> None:
        """Cancel every task submitted here that has not finished (a task already running
        finishes on its worker, and its result is dropped)."""
        self._executor.shutdown(wait=False)
        self._executor = self.client.get_executor(pure=False)

    def close(self) -> None:
        self._executor.shutdown(wait=False)
        self.client.close()
