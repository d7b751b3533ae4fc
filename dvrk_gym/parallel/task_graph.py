"""Run a graph of cached tasks on an executor, each after the tasks it needs.

A task is a module-level function (so a worker can import it) with keyword arguments, the
names of the tasks it needs, and a rough cost. The graph's order comes from
:class:`graphlib.TopologicalSorter`; the work runs on any
:class:`~dvrk_gym.parallel.executors.Executor` (this process, a local process pool, or a
Dask cluster), each call through :func:`call_task`. Each result, a JSON-able dict, is
cached in ``cache_dir/<name>.json`` (a :class:`~dvrk_gym.utils.run_folder.RunFolder`, written
by this process) with the wall time it took; a re-run loads the cached results and runs only
the rest, so an interrupted run resumes (a cached result cut short is moved aside and its
task run again). The cache knows results by task name only, not by the tasks' arguments or
code nor by which dvrk_gym made them: the caller puts it inside a run folder stamped with what
the results depend on, as ``dvrk-gym reproduce`` does (``<out>/tasks`` in its stamped ``<out>``,
whose stamp also holds dvrk_gym's source fingerprint and is checked before the graph runs).
Results do not depend on the executor: every task seeds itself and runs with one torch
thread. Local workers end with the process that started them, even when it is killed
(:func:`~dvrk_gym.utils.parent_watch.end_with_parent`).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import functools
import graphlib
import logging
import math
import os
import socket
import time
from collections.abc import Callable, Iterable
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from dvrk_gym.parallel.executors import Executor, local_executor, outcome_of
from dvrk_gym.parallel.progress_clock import running_clock
from dvrk_gym.utils.atomic import read_json
from dvrk_gym.utils.checks import check_file_stem
from dvrk_gym.utils.run_folder import RunFolder
from dvrk_gym.utils.torch_threads import torch_threads

BAR_FORMAT = "{desc} {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]"
"""The progress bar: tasks done, the share of the graph's work done (by ``cost_s``), the time
taken and left, the tasks running."""

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Task:
    """One unit of work.

    Attributes:
        name: unique name; also the cache file's stem.
        function: a module-level function returning a JSON-able dict.
        kwargs: its keyword arguments (picklable).
        needs: names of the tasks that must finish first.
        cost_s: rough wall time, seconds. Among ready tasks, the one with the most work
            riding on it (its cost plus that of every task that needs it, directly or
            not) starts first, so that the stages that unlock others are not kept waiting.
        files: keys of its result that name files it wrote (paths): a cached result whose
            files are gone is run again.
    """

    name: str
    function: Callable[..., dict[str, Any]]
    kwargs: dict[str, Any] = field(default_factory=dict)
    needs: tuple[str, ...] = ()
    cost_s: float = 1.0
    files: tuple[str, ...] = ()


class TaskError(RuntimeError):
    """A task raised, or its worker died; the message names it (finished tasks stay cached)."""


def locate_in_folder(path: str | os.PathLike, folder: str | os.PathLike) -> Path:
    """Where a file a run folder's result names lies now: ``path`` itself when it is inside
    ``folder`` or no longer moved; in a folder moved or copied since the result was written
    (results record absolute paths), the longest tail of ``path`` that is a file in ``folder``.
    """
    full, root = Path(os.path.abspath(path)), Path(os.path.abspath(folder))
    if not full.is_relative_to(root):
        for start in range(1, len(full.parts)):
            moved = root / Path(*full.parts[start:])
            if moved.is_file():
                return moved
    return full


def call_task(
    function: Callable[..., dict[str, Any]], kwargs: dict[str, Any], shared_folder: str | None = None
) -> tuple[dict[str, Any], float]:
    """Run one task where the executor puts it: ``(function(**kwargs), wall time in s)``.

    Raises:
        FileNotFoundError: ``shared_folder`` is given and does not exist here (a cluster
            worker that does not see the run's disk).
    """
    if shared_folder is not None and not Path(shared_folder).is_dir():
        raise FileNotFoundError(
            f"the run folder {shared_folder} is not on this worker's disk (host {socket.gethostname()}); "
            "on a cluster it must be on a disk every worker sees at the same path"
        )
    start = time.perf_counter()
    with torch_threads(1):  # the same numbers whatever the cores or workers, no oversubscription side by side
        result = function(**kwargs)
    return result, time.perf_counter() - start


def _read_result(path: Path, files: tuple[str, ...], root: Path) -> dict[str, Any]:
    """A cached task result; ValueError unless it is a JSON object with the task's wall time
    and the files its ``files`` keys name are in ``root``, the run folder (where they were
    written, or where they lie should it have been moved or copied since: :func:`locate_in_folder`)."""
    result = read_json(path)
    if not isinstance(result, dict) or not isinstance(result.get("wall_s"), (int, float)):
        raise ValueError("not a task result (a JSON object with its wall_s)")
    for key in files:
        named = result.get(key)
        located = locate_in_folder(named, root) if isinstance(named, str) else None
        # a copied folder's results name the original's files: one gone from the copy is gone
        if located is None or not located.is_relative_to(os.path.abspath(root)) or not located.is_file():
            raise ValueError(f"its {key!r} file {named!r} is gone from {root}: the task runs again")
    return result


def _sorter(tasks: list[Task]) -> graphlib.TopologicalSorter:
    """The graph's sorter, prepared; ValueError for repeated names, unknown needs or a cycle."""
    names = [task.name for task in tasks]
    for name in names:  # the name is its cache file's stem
        check_file_stem("task name", name)
    if len(set(names)) != len(names):
        raise ValueError(f"task names must be unique: {sorted(n for n in set(names) if names.count(n) > 1)}")
    for task in tasks:
        unknown = set(task.needs) - set(names)
        if unknown:
            raise ValueError(f"task {task.name!r} needs unknown tasks {sorted(unknown)}")
    sorter: graphlib.TopologicalSorter = graphlib.TopologicalSorter({task.name: task.needs for task in tasks})
    try:
        sorter.prepare()
    except graphlib.CycleError as error:
        raise ValueError(f"the tasks' needs form a cycle: {error.args[1]}") from None
    return sorter


def _priorities(tasks: list[Task]) -> dict[str, float]:
    """Each task's cost plus the costs of all the tasks that need it, directly or not."""
    below: dict[str, set[str]] = {task.name: set() for task in tasks}
    order = list(graphlib.TopologicalSorter({task.name: task.needs for task in tasks}).static_order())
    needs = {task.name: task.needs for task in tasks}
    for name in reversed(order):  # every task after all that need it: their sets are complete
        for need in needs[name]:
            below[need] |= {name} | below[name]
    cost = {task.name: task.cost_s for task in tasks}
    return {name: cost[name] + sum(cost[child] for child in below[name]) for name in cost}


def run_tasks(
    tasks: list[Task],
    *,
    cache_dir: Path,
    workers: int = 1,
    progress: bool = True,
    executor: Executor | None = None,
    shared_folder: Path | None = None,
    label: str = "run",
) -> dict[str, dict[str, Any]]:
    """Run (or load from ``cache_dir``) every task; returns ``{name: result}`` in the graph's order.

    Each result gets ``wall_s`` (its wall time when it ran, seconds) and ``cached``
    (True when this call loaded it).

    Args:
        tasks: the graph (needs must name tasks in the list; no cycles).
        cache_dir: where results are cached as JSON, by task name only (see the module docstring).
        workers: without ``executor``, local processes to run tasks in; 1 runs them here,
            one after another.
        progress: show a bar over the tasks.
        executor: where tasks run (not closed here); None: ``workers`` local ones.
        shared_folder: a folder the tasks write into: each checks first that it sees it
            where it runs (on a cluster, a worker without the run's disk fails clearly).
        label: the progress bar's name.

    Raises:
        TaskError: a task failed or its worker died (the tasks running are awaited and
            cached first; none starts after the failure).
        ValueError: a bad graph or ``workers``.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    sorter = _sorter(tasks)
    with RunFolder(cache_dir) as cache, contextlib.ExitStack() as stack:
        runner = executor if executor is not None else stack.enter_context(local_executor(workers))
        shared = None if shared_folder is None else str(shared_folder)
        return _GraphRun(tasks, sorter, cache, runner, shared, progress, label).run()


class _GraphRun:
    """One run of a graph: the cached results, the queue of ready tasks, those running."""

    def __init__(
        self,
        tasks: list[Task],
        sorter: graphlib.TopologicalSorter,
        cache: RunFolder,
        executor: Executor,
        shared: str | None,
        progress: bool,
        label: str,
    ) -> None:
        self.tasks, self.sorter, self.cache, self.executor, self.shared, self.progress = tasks, sorter, cache, executor, shared, progress
        self.by_name = {task.name: task for task in tasks}
        priority = _priorities(tasks)
        self.rank = {task.name: (-priority[task.name], index) for index, task in enumerate(tasks)}  # ties: the graph's order
        self.results: dict[str, dict[str, Any]] = {}
        for task in tasks:
            root = Path(shared) if shared is not None else cache.path.parent  # the run folder the files lie in
            found = cache.load(f"{task.name}.json", functools.partial(_read_result, files=task.files, root=root))
            if found is not None:
                self.results[task.name] = {**found, "cached": True}
        self.ready: list[str] = []
        self.running: dict[cf.Future, Task] = {}
        self.failure: TaskError | None = None
        # The bar counts each task's cost_s, not tasks: its estimate of the time left is then
        # not thrown by a graph whose few long tasks run first (counting tasks, reproduce
        # --quick's estimate after its first task was 12:15 with 33 s left; now 1:47, 40 s left).
        self.label = label
        self.work = {task.name: task.cost_s if math.isfinite(task.cost_s) and task.cost_s > 0 else 1.0 for task in tasks}
        done = sum(self.work[name] for name in self.results)
        self.bar = tqdm(total=sum(self.work.values()), initial=done, desc=self._tasks_done(), bar_format=BAR_FORMAT, disable=not progress)

    def run(self) -> dict[str, dict[str, Any]]:
        try:
            with running_clock(self.bar):  # its elapsed time moves while a long task runs
                self._loop()
        except BaseException:  # Ctrl-C or an error here: stop the workers now; finished tasks are cached
            self.executor.stop()
            raise
        finally:
            self.bar.close()
        if self.failure is not None:
            raise self.failure
        return {task.name: self.results[task.name] for task in self.tasks}

    def _loop(self) -> None:
        """Submit what is ready, collect what ends, until every task is done or one failed."""
        self._queue_ready()
        while self.ready or self.running:
            if self.failure is None:
                self._submit()
            if not self.running:
                break
            self._show(task.name for task in self.running.values())
            done, _ = cf.wait(self.running, return_when=cf.FIRST_COMPLETED)
            self._collect(done)
            if self.failure is None:
                self._queue_ready()

    def _tasks_done(self) -> str:
        return f"{self.label}: {len(self.results)}/{len(self.tasks)} tasks"

    def _show(self, running: Iterable[str]) -> None:
        """The bar's words: tasks finished of all before it, those running after it."""
        self.bar.set_description_str(self._tasks_done(), refresh=False)
        self.bar.set_postfix_str(", ".join(sorted(running)), refresh=False)

    def _queue_ready(self) -> None:
        """Queue the tasks whose needs have finished, best first; cached ones count as finished."""
        while self.sorter.is_active():
            names = self.sorter.get_ready()
            if not names:
                break
            for name in names:
                if name in self.results:
                    self.sorter.done(name)
                else:
                    self.ready.append(name)
        self.ready.sort(key=self.rank.__getitem__)

    def _submit(self) -> None:
        """Start the best ready tasks, as many as the executor runs at once."""
        while self.ready and len(self.running) < self.executor.capacity():
            task = self.by_name[self.ready.pop(0)]
            self.running[self.executor.submit(call_task, task.function, task.kwargs, self.shared)] = task

    def _collect(self, done: set[cf.Future]) -> None:
        lost = sorted(task.name for task in self.running.values())  # what was running, should a worker die
        for future in done:
            task = self.running.pop(future)
            outcome = outcome_of(task, future.result)
            if outcome.error is None:
                try:
                    self._finish(task, *outcome.result)
                except (TypeError, ValueError) as error:  # a result that is not JSON: as if the task had raised
                    if self.failure is None:
                        self.failure = TaskError(f"task {task.name!r} returned a result that cannot be saved as JSON: {error}")
            elif self.failure is None:
                if isinstance(outcome.error, BrokenProcessPool):  # a worker was killed (or ran out of memory): none can say which
                    self.failure = TaskError(f"a worker process died while running {lost}: {outcome.error}")
                else:
                    self.failure = TaskError(f"task {task.name!r} failed: {outcome.failure}")
                self.failure.__cause__ = outcome.error

    def _finish(self, task: Task, result: dict[str, Any], seconds: float) -> None:
        result = {**result, "wall_s": seconds}
        self.cache.write_json(f"{task.name}.json", result)
        self.results[task.name] = {**result, "cached": False}
        self.sorter.done(task.name)
        self._show(running.name for running in self.running.values())
        self.bar.update(self.work[task.name])
        message = f"{task.name}: {seconds:.0f} s"
        self.bar.write(message) if self.progress else logger.info(message)
