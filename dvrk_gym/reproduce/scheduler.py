"""Run a small graph of cached tasks, in worker processes when asked.

A task is a top-level function (so a worker process can import it) with keyword
arguments, the names of the tasks it needs, and a rough cost. Its result, a JSON-able
dict, is cached in ``cache_dir/<name>.json`` (a :class:`~dvrk_gym.utils.run_folder.RunFolder`)
with the wall time it took; a re-run loads the cached results and runs only the rest, so
an interrupted run resumes (a cached result cut short is moved aside and its task run
again). Results do not depend on the number of workers: every task seeds itself and runs
with one torch thread. Worker processes end with the process that started them, even when
it is killed (:func:`~dvrk_gym.utils.parent_watch.end_with_parent`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from dvrk_gym.utils.parent_watch import end_with_parent
from dvrk_gym.utils.run_folder import RunFolder
from dvrk_gym.utils.torch_threads import torch_threads

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
    """

    name: str
    function: Callable[..., dict[str, Any]]
    kwargs: dict[str, Any] = field(default_factory=dict)
    needs: tuple[str, ...] = ()
    cost_s: float = 1.0


class TaskError(RuntimeError):
    """A task raised; the message names it (finished tasks stay cached)."""


def _call(function: Callable[..., dict[str, Any]], kwargs: dict[str, Any]) -> tuple[dict[str, Any], float]:
    start = time.perf_counter()
    with torch_threads(1):  # the same numbers on any machine, no oversubscription side by side
        result = function(**kwargs)
    return result, time.perf_counter() - start


def _read_result(path: Path) -> dict[str, Any]:
    """A cached task result; ValueError unless it is a JSON object with the task's wall time."""
    result = json.loads(path.read_text())
    if not isinstance(result, dict) or not isinstance(result.get("wall_s"), (int, float)):
        raise ValueError("not a task result (a JSON object with its wall_s)")
    return result


def _check_graph(tasks: list[Task]) -> None:
    names = [task.name for task in tasks]
    if len(set(names)) != len(names):
        raise ValueError(f"task names must be unique: {sorted(n for n in set(names) if names.count(n) > 1)}")
    for task in tasks:
        unknown = set(task.needs) - set(names)
        if unknown:
            raise ValueError(f"task {task.name!r} needs unknown tasks {sorted(unknown)}")
    done: set[str] = set()
    pending = list(tasks)
    while pending:
        ready = [task for task in pending if set(task.needs) <= done]
        if not ready:
            raise ValueError(f"the tasks' needs form a cycle: {sorted(task.name for task in pending)}")
        done |= {task.name for task in ready}
        pending = [task for task in pending if task.name not in done]


def _priorities(tasks: list[Task]) -> dict[str, float]:
    """Each task's cost plus the costs of all the tasks that need it, directly or not."""
    dependents: dict[str, set[str]] = {task.name: set() for task in tasks}
    for task in tasks:
        for need in task.needs:
            dependents[need].add(task.name)
    cost = {task.name: task.cost_s for task in tasks}

    def below(name: str) -> set[str]:
        found = set(dependents[name])
        for child in dependents[name]:
            found |= below(child)
        return found

    return {name: cost[name] + sum(cost[child] for child in below(name)) for name in cost}


def run_tasks(tasks: list[Task], cache_dir: Path, workers: int = 1, progress: bool = True) -> dict[str, dict[str, Any]]:
    """Run (or load from ``cache_dir``) every task; returns ``{name: result}``.

    Each result gets ``wall_s`` (its wall time when it ran, seconds) and ``cached``
    (True when this call loaded it).

    Args:
        tasks: the graph (needs must name tasks in the list; no cycles).
        cache_dir: where results are cached as JSON.
        workers: processes to run tasks in; 1 runs them here, one after another.
        progress: show a bar over the tasks.

    Raises:
        TaskError: a task failed (the others that were running are awaited first).
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    _check_graph(tasks)
    with RunFolder(cache_dir) as cache:
        return _run_graph(tasks, cache, workers, progress)


def _run_graph(tasks: list[Task], cache: RunFolder, workers: int, progress: bool) -> dict[str, dict[str, Any]]:
    results: dict[str, dict[str, Any]] = {}
    for task in tasks:
        found = cache.load(f"{task.name}.json", _read_result)
        if found is not None:
            results[task.name] = {**found, "cached": True}
    priority = _priorities(tasks)
    pending = sorted((task for task in tasks if task.name not in results), key=lambda task: -priority[task.name])
    bar = tqdm(total=len(tasks), initial=len(results), desc="reproduce", unit="task", disable=not progress)

    def finish(task: Task, result: dict[str, Any], seconds: float) -> None:
        result = {**result, "wall_s": seconds}
        cache.write_json(f"{task.name}.json", result)
        results[task.name] = {**result, "cached": False}
        bar.update(1)
        message = f"{task.name}: {seconds:.0f} s"
        bar.write(message) if progress else logger.info(message)

    def ready() -> list[Task]:
        return [task for task in pending if all(need in results for need in task.needs)]

    try:
        if workers == 1:
            while pending:
                task = ready()[0]
                pending.remove(task)
                bar.set_postfix_str(task.name)
                try:
                    outcome = _call(task.function, task.kwargs)
                except Exception as error:
                    raise TaskError(f"task {task.name!r} failed: {type(error).__name__}: {error}") from error
                finish(task, *outcome)
        else:
            _run_in_pool(pending, workers, ready, finish, bar)
    finally:
        bar.close()
    return {task.name: results[task.name] for task in tasks}  # in the graph's order


@contextlib.contextmanager
def _stop_workers_on_interrupt() -> Iterator[None]:
    """On Ctrl-C (or any error escaping the loop) stop the workers now rather than let
    them finish their tasks; finished tasks are cached already."""
    try:
        yield
    except BaseException:
        for child in multiprocessing.active_children():
            child.terminate()
        raise


def _run_in_pool(
    pending: list[Task], workers: int, ready: Callable[[], list[Task]], finish: Callable[[Task, dict, float], None], bar: Any
) -> None:
    running: dict[Future, Task] = {}
    failure: TaskError | None = None
    context = multiprocessing.get_context("spawn")  # no forked torch or pybullet state
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=end_with_parent, initargs=(os.getpid(),))
    with pool, _stop_workers_on_interrupt():
        while pending or running:
            if failure is None:
                for task in ready():
                    if len(running) >= workers:
                        break
                    pending.remove(task)
                    running[pool.submit(_call, task.function, task.kwargs)] = task
            if not running:
                break
            bar.set_postfix_str(", ".join(sorted(task.name for task in running.values())))
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            lost = sorted(task.name for task in running.values())  # what was running, should a worker die
            for future in done:
                task = running.pop(future)
                try:
                    finish(task, *future.result())
                except BrokenProcessPool as error:  # a worker was killed (or ran out of memory): no task can say which
                    if failure is None:
                        failure = TaskError(f"a worker process died while running {lost}: {error}")
                        failure.__cause__ = error
                except Exception as error:  # noqa: BLE001  (reported after the running tasks end)
                    if failure is None:
                        failure = TaskError(f"task {task.name!r} failed: {type(error).__name__}: {error}")
                        failure.__cause__ = error
    if failure is not None:
        raise failure
