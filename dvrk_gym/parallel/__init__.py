"""Where work runs, for the sweep and the reproduction alike: an executor interface with
local and Dask implementations, and a graph of cached tasks run on any of them.

>>> from dvrk_gym.parallel import LocalExecutor
>>> with LocalExecutor(workers=2) as executor:  # doctest: +SKIP
...     outcomes = list(executor.map_unordered(abs, [-1, -2]))

On a Dask cluster, ``DaskExecutor("tcp://host:8786")`` from
:mod:`dvrk_gym.parallel.dask_executor` (the ``dask`` extra) takes the place of
``LocalExecutor``, with the same results. Nothing here knows the simulator.
"""

from dvrk_gym.parallel.executors import Executor, FuturesExecutor, InlineExecutor, LocalExecutor, Outcome, local_executor
from dvrk_gym.parallel.task_graph import Task, TaskError, run_tasks

__all__ = ["Executor", "FuturesExecutor", "InlineExecutor", "LocalExecutor", "Outcome", "Task", "TaskError", "local_executor", "run_tasks"]
