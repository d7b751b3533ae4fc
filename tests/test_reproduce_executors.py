"""``reproduce`` on the shared executors (dvrk_gym.parallel): tasks in dependency order on any
executor, a worker without the run folder refused, ``--scheduler`` checked, and the quick
profile on a 2-worker Dask LocalCluster giving what local processes give, file for file."""

import io
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from reproduction_files import files_that_differ
from workers_for_tests import deaf_to_sigterm, die_once, import_pybullet, record, scratch_then_wait, sleep_for, square_or_die

from dvrk_gym.cli.main import main
from dvrk_gym.parallel.executors import InlineExecutor, LocalExecutor
from dvrk_gym.parallel.task_graph import Task, TaskError, run_tasks
from dvrk_gym.reproduce import TINY, ReproduceConfig, run_reproduce
from dvrk_gym.reproduce.run import seeded_results


def _graph(log: Path) -> list[Task]:
    def step(name, needs=(), cost=1.0):
        return Task(name, record, {"name": name, "log": str(log), "needs_seen": needs}, needs=needs, cost_s=cost)

    return [step("root", cost=5), step("a", ("root",)), step("b", ("root",)), step("c", ("a", "b")), step("free", cost=2)]


@pytest.mark.parametrize("make_executor", [InlineExecutor, lambda: LocalExecutor(workers=2)], ids=["inline", "local-2"])
def test_tasks_run_after_what_they_need_on_any_executor(tmp_path, make_executor):
    with make_executor() as executor:
        results = run_tasks(_graph(tmp_path / "log.txt"), cache_dir=tmp_path / "cache", progress=False, executor=executor)
    assert sorted((tmp_path / "log.txt").read_text().split()) == ["a", "b", "c", "free", "root"]  # each once, needs first
    assert list(results) == ["root", "a", "b", "c", "free"] and not any(r["cached"] for r in results.values())
    pids = {r["pid"] for r in results.values()}
    assert (pids == {os.getpid()}) == isinstance(executor, InlineExecutor)  # inline runs here, a pool elsewhere


def test_the_progress_bar_counts_each_tasks_cost_so_its_estimate_is_not_thrown_by_long_tasks_first(tmp_path, monkeypatch, capsys):
    """It counted tasks: reproduce's two long tasks run first, and its first estimate of the
    time left was several times too long."""
    from dvrk_gym.parallel import task_graph

    bars = []

    class Bar(task_graph.tqdm):  # the real bar, its total and steps kept
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.steps = []
            bars.append(self)

        def update(self, n=1):
            self.steps.append(n)
            return super().update(n)

    monkeypatch.setattr(task_graph, "tqdm", Bar)
    graph = _graph(tmp_path / "log.txt")  # costs: root 5, free 2, a, b and c 1 each
    with InlineExecutor() as executor:
        run_tasks(graph[:2], cache_dir=tmp_path / "cache", executor=executor)  # root and a, cached for the next run
        run_tasks(graph, cache_dir=tmp_path / "cache", executor=executor)
    assert (bars[0].total, bars[0].n) == (6.0, 6.0)
    assert (bars[1].total, bars[1].initial, sorted(bars[1].steps)) == (10.0, 6.0, [1.0, 1.0, 2.0])
    assert bars[1].desc == "run: 5/5 tasks" and "100%|" in capsys.readouterr().err


def test_the_progress_bar_clock_runs_while_a_long_task_runs(tmp_path, monkeypatch, capsys):
    """It was redrawn only when a task ended: reproduce --quick showed 0% at 00:00 for
    minutes, like a hung run."""
    from dvrk_gym.parallel import progress_clock

    monkeypatch.setattr(progress_clock, "MIN_REDRAW_S", 0.25)
    with LocalExecutor(workers=1) as executor:
        run_tasks([Task("long", sleep_for, {"seconds": 1.6})], cache_dir=tmp_path / "cache", executor=executor)
    drawn = capsys.readouterr().err.split("\r")
    assert any("run: 0/1 tasks" in line and "[00:01<" in line for line in drawn), drawn  # the clock, before it ended


def test_a_disabled_bar_gets_no_clock_thread_and_a_clock_thread_ends_with_its_block():
    from dvrk_gym.parallel.progress_clock import running_clock
    from dvrk_gym.parallel.task_graph import tqdm

    def clocks():
        return [thread for thread in threading.enumerate() if thread.name == "progress-clock"]

    with tqdm(total=1, disable=True) as bar, running_clock(bar):
        assert not clocks()
    with tqdm(total=1, file=io.StringIO()) as bar, running_clock(bar):
        assert len(clocks()) == 1
    assert not clocks()


def test_a_task_that_does_not_see_the_shared_folder_fails_saying_so(tmp_path):
    graph = [Task("a", record, {"name": "a", "log": str(tmp_path / "log.txt")})]
    with pytest.raises(TaskError, match=r"task 'a' failed: FileNotFoundError: the run folder .*gone is not on this worker's disk"):
        run_tasks(graph, cache_dir=tmp_path / "cache", progress=False, shared_folder=tmp_path / "gone")
    assert not (tmp_path / "log.txt").exists()  # refused before it ran


def test_a_local_pool_starts_again_after_a_worker_died(tmp_path):
    flag = tmp_path / "flag"
    with LocalExecutor(workers=1) as executor:
        future = executor.submit(die_once, str(flag))
        assert type(future.exception()).__name__ == "BrokenProcessPool"
        assert executor.submit(die_once, str(flag)).result() == "survived"


def test_one_dead_worker_fails_only_its_own_item():
    """A worker killed (out of memory, say) broke the pool and failed every item of a sweep with it."""
    with LocalExecutor(workers=2) as executor:
        outcomes = {o.item: o for o in executor.map_unordered(square_or_die, [1, 2, -3, 4, 5, 6])}
    assert {item: o.result for item, o in outcomes.items() if o.error is None} == {1: 1, 2: 4, 4: 16, 5: 25, 6: 36}
    assert type(outcomes[-3].error).__name__ == "BrokenProcessPool"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--scheduler", "localhost"], "the scheduler address 'localhost' is malformed (missing port"),
        (["--scheduler", "tcp://127.0.0.1:9", "--connect-timeout", "0.5"], "cannot reach a Dask scheduler at 'tcp://127.0.0.1:9'"),
    ],
)
def test_reproduce_refuses_a_bad_scheduler_in_one_line(capsys, tmp_path, arguments, message):
    pytest.importorskip("distributed")
    assert main(["reproduce", "--quick", "--out", str(tmp_path / "run"), "--no-progress", *arguments]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "run" / "tasks").exists()  # nothing ran


@pytest.mark.slow
def test_reproduce_on_a_dask_cluster_gives_what_a_local_process_gives(tmp_path, tiny_reproduction):
    """Every stage of a reproduction (the tiny profile: all of the quick run's tasks, on
    budgets that keep CI short) on a LocalCluster of 2 single-thread workers reached at its
    address as --scheduler would, against the same run in one local process (2 local
    processes give the same numbers: test_reproduce.test_two_workers_give_the_same_numbers)."""
    distributed = pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    local = tiny_reproduction
    # dashboard_address ":0": any free port for the HTTP server; None still takes 8787 (distributed 2026.8), so two clusters at once warn
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster,
        DaskExecutor(cluster.scheduler_address) as dask,
    ):
        on_dask = run_reproduce(ReproduceConfig(out=tmp_path / "dask", profile=TINY, progress=False), dask)
    assert on_dask.data["settings"]["executor"].startswith(f"Dask scheduler {cluster.scheduler_address} (2 workers, 2 threads)")
    assert seeded_results(json.loads(on_dask.results.read_text())) == seeded_results(json.loads(local.results.read_text()))
    assert files_that_differ(local.report.parent, tmp_path / "dask") == []
    assert len(list((tmp_path / "dask" / "debridement").glob("*.json"))) == 6


@pytest.mark.parametrize("workers", [0, 10**6, True, 2.0])
def test_a_local_pool_refuses_worker_counts_out_of_bounds(workers):
    with pytest.raises(ValueError, match=r"expected an int in \[1, 1024\]"):
        LocalExecutor(workers=workers)


def test_the_command_lines_workers_import_pybullet_without_its_banner(capfd):
    """Each spawned worker printed "pybullet build time: ..." into the progress bar of
    reproduce --quick (twice, two workers); the command line's pool imports it quietly."""
    from dvrk_gym.sim.physics.quiet_import import import_pybullet_quietly

    for setup, banner in ((None, True), (import_pybullet_quietly, False)):
        with LocalExecutor(workers=1, setup=setup) as executor:
            assert executor.submit(import_pybullet).result() is (setup is not None)  # the setup imported it first
        assert ("pybullet build time" in capfd.readouterr().err) is banner
    import argparse

    from dvrk_gym.cli.options import make_executor

    pool = make_executor(argparse.Namespace(scheduler=None, workers=2))
    assert isinstance(pool, LocalExecutor) and pool.setup is import_pybullet_quietly


def test_a_local_pool_takes_a_numpy_int():
    import numpy as np

    assert LocalExecutor(workers=np.int64(2)).workers == 2


def test_an_item_alone_in_the_pool_that_kills_its_worker_runs_once(tmp_path):
    flag = tmp_path / "flag"
    with LocalExecutor(workers=1) as executor:  # one worker: each item runs alone
        (outcome,) = executor.map_unordered(die_once, [str(flag)])
    assert type(outcome.error).__name__ == "BrokenProcessPool" and flag.exists()


def test_a_dask_result_is_let_go_on_its_worker_once_its_outcome_is_taken():
    """A held future keeps its result on its worker: a worker lost later took every finished
    unit's result with it, and the cluster ran those units again (the scheduler's log:
    "caused the cluster to lose already computed task(s), which will be recomputed")."""
    distributed = pytest.importorskip("distributed")
    from dvrk_gym.parallel.dask_executor import DaskExecutor

    with (
        distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster,
        DaskExecutor(cluster.scheduler_address) as dask,
    ):
        outcomes = dask.map_unordered(abs, [-1, -2, -3])
        taken = [next(outcomes).result]
        deadline = time.monotonic() + 30
        while len(dask.client.futures) > 2 and time.monotonic() < deadline:  # the client releases on its own thread
            time.sleep(0.05)
        held = len(dask.client.futures)  # the results the cluster keeps for this client
        taken += [outcome.result for outcome in outcomes]
    assert held == 2  # the two outcomes not taken yet
    assert sorted(taken) == [1, 2, 3]


def test_a_failure_without_words_still_says_what_happened():
    """A unit cancelled when the Dask scheduler died read ``CancelledError: `` and no more."""
    import concurrent.futures as cf

    from dvrk_gym.parallel.executors import Outcome

    assert Outcome(item=1, error=ValueError("bad seed")).failure == "ValueError: bad seed"
    assert "the scheduler, or the connection to it, was lost" in Outcome(item=1, error=cf.CancelledError()).failure
    assert Outcome(item=1, error=RuntimeError()).failure == "RuntimeError: (no message)"
    assert Outcome(item=1, result=2).failure == ""


def test_workers_stopped_as_by_ctrl_c_leave_no_semaphore_behind():
    """tqdm's default lock is a named semaphore; workers stopped mid-run cannot unlink it, and
    the resource tracker warned of leaked semaphores as `reproduce` ended after Ctrl-C."""
    script = (
        "import sys; sys.path.insert(0, sys.argv[1])\n"
        "from workers_for_tests import disabled_bar\n"
        "from dvrk_gym.parallel.executors import LocalExecutor\n"
        "if __name__ == '__main__':\n"
        "    pool = LocalExecutor(2)\n"
        "    print(sorted(outcome.result for outcome in pool.map_unordered(disabled_bar, [1, 2, 3, 4])))\n"
        "    pool.stop()\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(Path(__file__).parent)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "[1, 2, 3, 4]", done.stderr
    assert "leaked semaphore" not in done.stderr  # the tracker writes to the same stderr, before the pipe closes


def test_a_worker_stopped_as_by_ctrl_c_deletes_its_scratch_folder(tmp_path, monkeypatch):
    """A stopped worker ended at once and left its unit's folder (0.76 MB at a quick budget)
    in the temporary folder until the next sweep on the host deleted it."""
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the worker, spawned after this, makes its folder here
    with LocalExecutor(workers=1) as pool:
        future = pool.submit(scratch_then_wait, 60.0)
        deadline = time.monotonic() + 60
        while not list(tmp_path.glob("dvrk_gym_sweep_*/phase1.npz")) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert list(tmp_path.glob("dvrk_gym_sweep_*")), "the worker made no scratch folder"
        pool.stop()
    assert future.cancelled() or future.exception(timeout=30) is not None  # it did not finish its wait
    assert not list(tmp_path.glob("dvrk_gym_sweep_*"))


def test_stop_kills_a_worker_that_does_not_end_on_sigterm_within_its_grace(tmp_path, monkeypatch):
    """Its SIGTERM handler runs only once a long C call returns: stop() waited 5 s and left
    the worker running its call."""
    from dvrk_gym.parallel import executors

    monkeypatch.setattr(executors, "STOP_GRACE_S", 0.5)
    pool = LocalExecutor(workers=1)
    try:
        future = pool.submit(deaf_to_sigterm, 60.0, str(tmp_path / "began"))
        deadline = time.monotonic() + 60
        while not (tmp_path / "began").exists() and time.monotonic() < deadline:  # the call has begun
            time.sleep(0.05)
        processes = list(pool._pool._processes.values())
        began = time.monotonic()
        pool.stop()
        assert time.monotonic() - began < 10.0 and not any(process.is_alive() for process in processes)
        assert future.cancelled() or future.exception(timeout=30) is not None
    finally:
        pool.close()
