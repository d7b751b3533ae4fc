"""Helpers of the reliability tests: the command line in a fresh process, a tiny
reproduction profile, the parts of a run's results that do not depend on the clock."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from dvrk_gym.reproduce import TINY
from dvrk_gym.reproduce.run import seeded_results

ROOT = Path(__file__).resolve().parents[2]

TINY_PROFILE = TINY.to_dict()
"""The tiny reproduction (:data:`dvrk_gym.reproduce.TINY`) as ``--profile`` reads it."""


def deterministic(value: Any) -> Any:
    """A results tree without its wall-clock times and run records (:func:`dvrk_gym.reproduce.run.seeded_results`)."""
    return seeded_results(value)


def cli_command(*arguments: str) -> list[str]:
    """``dvrk-gym ARGUMENTS`` as a command for this interpreter (this worktree's package)."""
    return [sys.executable, "-m", "dvrk_gym.cli.main", *arguments]


def environment() -> dict[str, str]:
    """The environment of a fresh process that imports this worktree's dvrk_gym."""
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def run_cli(*arguments: str, timeout_s: float = 300.0) -> subprocess.CompletedProcess:
    """Run ``dvrk-gym ARGUMENTS`` in a fresh process; its exit status and output."""
    return subprocess.run(cli_command(*arguments), capture_output=True, text=True, timeout=timeout_s, env=environment(), cwd=ROOT)


def write_profile(folder: Path, profile: dict[str, Any] = TINY_PROFILE) -> Path:
    """A profile file for ``dvrk-gym reproduce --profile``."""
    path = folder / f"{profile['name']}.json"
    path.write_text(json.dumps(profile))
    return path


def files_in(folder: Path) -> set[str]:
    """Every file under ``folder``, relative to it (an empty set if it does not exist)."""
    if not folder.exists():
        return set()
    return {str(path.relative_to(folder)) for path in folder.rglob("*") if path.is_file()}
