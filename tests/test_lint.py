"""The code passes its linter, its formatter and its type check, as configured in pyproject.toml.

Each tool runs as a subprocess of this interpreter (``python -m ruff``, ``python -m mypy``)
from the project's root, so it reads the project's configuration and checks what a
contributor's ``ruff check``, ``ruff format --check`` and ``mypy`` check. They belong to the
default test command; ``-m "not lint"`` leaves them out while a change is in progress.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.lint


def _run(tool: str, *args: str) -> subprocess.CompletedProcess[str]:
    if importlib.util.find_spec(tool) is None:
        pytest.fail(f"{tool} is not installed; the test tools come with: pip install -e '.[dev]'")
    return subprocess.run([sys.executable, "-m", tool, *args], cwd=ROOT, capture_output=True, text=True, check=False)


def _report(result: subprocess.CompletedProcess[str]) -> str:
    command = " ".join(result.args[2:])
    return f"`{command}` exited with {result.returncode}:\n{result.stdout}{result.stderr}"


def test_ruff_check_finds_nothing():
    result = _run("ruff", "check", "--no-cache")
    assert result.returncode == 0, _report(result)


def test_ruff_format_would_change_nothing():
    result = _run("ruff", "format", "--check", "--no-cache")
    assert result.returncode == 0, _report(result)


@pytest.mark.slow
def test_mypy_finds_no_type_error_in_the_public_api():
    result = _run("mypy")
    assert result.returncode == 0, _report(result)
