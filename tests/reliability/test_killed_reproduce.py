"""``dvrk-gym reproduce`` killed with SIGKILL: no worker outlives it, and the same command
resumes to the results of a run that was never interrupted."""

import json
import signal
import subprocess
import time

import psutil
import pytest
from faults import ROOT, cli_command, deterministic, environment, write_profile

from dvrk_gym.reproduce import TINY, Profile

pytestmark = pytest.mark.slow


def _start(profile_path, out, log):
    arguments = ("reproduce", "--profile", str(profile_path), "--out", str(out), "--workers", "2", "--no-progress")
    return subprocess.Popen(cli_command(*arguments), stdout=log, stderr=subprocess.STDOUT, env=environment(), cwd=ROOT)


def _command_line(process: psutil.Process) -> str:
    """The process's command line, or "" once it has ended or is a zombie (a child that
    exits while the run's processes are listed: a race, not a worker)."""
    try:
        return " ".join(process.cmdline())
    except psutil.NoSuchProcess:  # ZombieProcess included
        return ""


def _wait_for_workers_and_a_result(parent: psutil.Process, out, timeout_s: float = 240.0) -> list[psutil.Process]:
    """The run's processes once both workers run and at least one task result is cached."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        workers = [p for p in parent.children(recursive=True) if "spawn_main" in _command_line(p)]
        if len(workers) >= 2 and any((out / "tasks").glob("*.json")):
            return parent.children(recursive=True)
        time.sleep(0.2)
    raise AssertionError(f"no worker and result within {timeout_s} s")


def test_sigkill_leaves_no_worker_and_the_rerun_matches_an_uninterrupted_run(tmp_path, tiny_reproduction):
    profile_path = write_profile(tmp_path)
    out = tmp_path / "killed"
    with open(tmp_path / "first.log", "w") as log:
        first = _start(profile_path, out, log)
        parent = psutil.Process(first.pid)
        children = _wait_for_workers_and_a_result(parent, out)
        cached_before = {path.stem for path in (out / "tasks").glob("*.json")}
        first.send_signal(signal.SIGKILL)
        first.wait()
    _, alive = psutil.wait_procs(children, timeout=15)
    assert not alive, f"processes outlived the killed run: {[(p.pid, _command_line(p)) for p in alive]}"
    assert not (out / "results.json").exists()

    again = subprocess.run(
        cli_command("reproduce", "--profile", str(profile_path), "--out", str(out), "--workers", "2", "--no-progress"),
        capture_output=True,
        text=True,
        env=environment(),
        cwd=ROOT,
        timeout=600,
    )
    assert again.returncode == 0, again.stderr[-2000:]
    resumed = json.loads((out / "results.json").read_text())
    assert cached_before <= set(resumed["task_cached"])  # what finished before the kill was not run again
    assert not list(out.rglob(".*.partial*"))

    assert Profile.from_dict(json.loads(profile_path.read_text())) == TINY  # the profile of the uninterrupted run compared with
    assert deterministic(resumed) == deterministic(json.loads(tiny_reproduction.results.read_text()))
