"""Fault injection: random SIGKILLs of ``dvrk-gym reproduce``, each followed by a resume.

Run: python benchmarks/bench_faults.py  [--kills 20] [--workers 2] [--seed 0] [--profile FILE] [--out DIR]

First an uninterrupted run of a small profile (:data:`dvrk_gym.reproduce.TINY` unless
``--profile`` gives another) is timed and kept as the reference. Then, ``--kills`` times, a
fresh run is started in its own folder and killed with SIGKILL at a random moment within
the reference's wall time; the processes it started are checked to end (none may outlive
it by 15 s), and the same command is run again to the end. Each resume must finish, leave
no temporary file (in the run's folder, nor a scratch folder of an ended process in the
system's temporary folder), and give results.json equal to the reference's, but for wall-clock
times (:func:`dvrk_gym.reproduce.run.seeded_results`). Prints one line per kill and the
counts. Takes about 1.5 times the reference's wall time per kill (about 30 minutes for 20
kills of the tiny profile on 2 cores).
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

from dvrk_gym.cli.options import check_flag_bounds
from dvrk_gym.reproduce import TINY
from dvrk_gym.reproduce.run import seeded_results
from dvrk_gym.sim.physics.mirror import SCRATCH_PREFIX as DISPLAY_SCRATCH_PREFIX
from dvrk_gym.sweep.unit import SCRATCH_PREFIX as SWEEP_SCRATCH_PREFIX
from dvrk_gym.utils.parent_watch import orphaned_scratch

ORPHAN_GRACE_S = 15.0
SCRATCH_PREFIXES = (SWEEP_SCRATCH_PREFIX, DISPLAY_SCRATCH_PREFIX)
"""The package's scratch folders in the system's temporary folder (:class:`~dvrk_gym.utils.parent_watch.ScratchFolder`)."""


def orphaned_scratch_folders() -> set[Path]:
    """The package's scratch folders that ended processes on this host left."""
    return {folder for prefix in SCRATCH_PREFIXES for folder in orphaned_scratch(prefix)}


def command(profile: Path, out: Path, workers: int) -> list[str]:
    return [sys.executable, "-m", "dvrk_gym.cli.main", "reproduce", "--profile", str(profile), "--out", str(out)] + [
        "--workers",
        str(workers),
        "--no-progress",
    ]


def run_to_end(profile: Path, out: Path, workers: int) -> tuple[int, float, str]:
    """Exit status, wall seconds and the end of stderr of one complete run."""
    start = time.perf_counter()
    result = subprocess.run(command(profile, out, workers), capture_output=True, text=True)
    return result.returncode, time.perf_counter() - start, result.stderr[-500:]


def kill_at(profile: Path, out: Path, workers: int, after_s: float) -> tuple[int, int, bool]:
    """Start a run, SIGKILL it ``after_s`` seconds in; (processes it had started, how many outlived it, whether it had ended first)."""
    process = subprocess.Popen(command(profile, out, workers), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    parent = psutil.Process(process.pid)
    deadline = time.monotonic() + after_s
    children: dict[int, psutil.Process] = {}
    while time.monotonic() < deadline and process.poll() is None:
        try:
            children.update({child.pid: child for child in parent.children(recursive=True)})
        except psutil.NoSuchProcess:
            break
        time.sleep(0.1)
    ended_first = process.poll() is not None
    if not ended_first:
        children.update({child.pid: child for child in parent.children(recursive=True)})
        process.send_signal(signal.SIGKILL)
    process.wait()
    _, alive = psutil.wait_procs(list(children.values()), timeout=ORPHAN_GRACE_S)
    for orphan in alive:  # report them, and do not leave them running
        orphan.kill()
    return len(children), len(alive), ended_first


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20, help="killed runs, each resumed (default: %(default)s)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes of each run (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seeds the kill times (default: %(default)s)")
    parser.add_argument("--profile", type=Path, help="a profile JSON (default: dvrk_gym.reproduce.TINY)")
    parser.add_argument("--out", type=Path, help="where the runs go (default: a temporary folder, removed at the end)")
    args = parser.parse_args()
    check_flag_bounds(parser, args, {"kills": (0, 10**4), "workers": (1, 64), "seed": (0, 2**31 - 1)})
    root = args.out or Path(tempfile.mkdtemp(prefix="bench_faults_"))
    root.mkdir(parents=True, exist_ok=True)
    profile = args.profile or root / "tiny.json"
    if args.profile is None:
        profile.write_text(json.dumps(TINY.to_dict()))
    try:
        status, reference_s, err = run_to_end(profile, root / "reference", args.workers)
        if status != 0:
            raise SystemExit(f"the reference run failed ({status}): {err}")
        reference = seeded_results(json.loads((root / "reference" / "results.json").read_text()))
        print(f"reference: {reference_s:.0f} s, {args.workers} workers; killing {args.kills} runs at random times within it")
        rng = np.random.default_rng(args.seed)
        counts = {"killed": 0, "resumed": 0, "identical": 0, "orphans": 0, "partial files": 0}
        for i in range(args.kills):
            out = root / f"kill{i:02d}"
            scratch_before = orphaned_scratch_folders()
            after = float(rng.uniform(0.02, 0.98) * reference_s)
            started, orphans, ended_first = kill_at(profile, out, args.workers, after)
            cached = len(list((out / "tasks").glob("*.json"))) if (out / "tasks").exists() else 0
            status, resume_s, err = run_to_end(profile, out, args.workers)
            identical = status == 0 and seeded_results(json.loads((out / "results.json").read_text())) == reference
            partial = len(list(out.rglob(".*.partial*"))) + len(orphaned_scratch_folders() - scratch_before)
            counts["killed"] += not ended_first
            counts["resumed"] += status == 0
            counts["identical"] += identical
            counts["orphans"] += orphans
            counts["partial files"] += partial
            note = " (it had finished first)" if ended_first else ""
            print(
                f"kill {i + 1:>2} at {after:5.1f} s{note}: {started} processes, {orphans} outlived it; {cached} tasks cached; "
                f"resume {'finished' if status == 0 else f'FAILED ({status}): {err}'} in {resume_s:.0f} s, "
                f"results {'identical' if identical else 'DIFFERENT'}, {partial} temporary files left"
            )
        print(
            f"{counts['killed']} kills, {counts['resumed']} resumes finished, {counts['identical']} identical to the reference, "
            f"{counts['orphans']} orphan processes, {counts['partial files']} temporary files left"
        )
    finally:
        if args.out is None:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
