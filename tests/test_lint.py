"""The code passes its linter, its formatter and its type check, as configured in pyproject.toml.

Each tool runs as a subprocess of this interpreter (``python -m ruff``, ``python -m mypy``)
from the project's root, so it reads the project's configuration and checks what a
contributor's ``ruff check``, ``ruff format --check`` and ``mypy`` check. They belong to the
default test command; ``-m "not lint"`` leaves them out while a change is in progress.
"""

from __future__ import annotations

import ast
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


# A public function takes at most four parameters by position; the rest are keyword-only.
MAX_POSITIONAL = 4
# The numba kernels take flat arrays in a fixed order (machine code, called from float_paths
# only); outline_gap measures between two outlines given alike, (size, position, yaw) each.
POSITIONAL_EXEMPT_MODULES = {"dvrk_gym/sim/compiled/kernels.py"}
POSITIONAL_EXEMPT = {"dvrk_gym/sim/table/layout.py": {"outline_gap"}}


def _public_functions(tree: ast.Module):
    """(qualified name, node) of the module's public functions and its public classes' methods."""
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not node.name.startswith("_"):
            yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, ast.FunctionDef | ast.AsyncFunctionDef) and (item.name == "__init__" or not item.name.startswith("_")):
                    yield f"{node.name}.{item.name}", item


def positional_heavy(source: str, exempt: set[str] | frozenset[str] = frozenset()) -> list[str]:
    """The public functions of ``source`` that take more than MAX_POSITIONAL parameters by position."""
    found = []
    for name, node in _public_functions(ast.parse(source)):
        positional = [a.arg for a in node.args.posonlyargs + node.args.args if a.arg not in ("self", "cls")]
        if len(positional) > MAX_POSITIONAL and name not in exempt:
            found.append(f"{name}({', '.join(positional)})")
    return found


def test_positional_heavy_finds_a_long_positional_signature_and_passes_a_keyword_only_one():
    assert positional_heavy("def f(a, b, c, d, e): ...") == ["f(a, b, c, d, e)"]
    assert positional_heavy("class C:\n    def m(self, a, b, c, d, e): ...") == ["C.m(a, b, c, d, e)"]
    assert positional_heavy("def f(a, b, c, d, *, e): ...\ndef _g(a, b, c, d, e): ...") == []


def test_public_functions_take_at_most_four_parameters_by_position():
    found = []
    for path in sorted((ROOT / "dvrk_gym").rglob("*.py")):
        relative = path.relative_to(ROOT).as_posix()
        if relative in POSITIONAL_EXEMPT_MODULES:
            continue
        exempt = POSITIONAL_EXEMPT.get(relative, frozenset())
        found += [f"{relative}: {item}" for item in positional_heavy(path.read_text(encoding="utf-8"), exempt)]
    assert not found, "make the parameters after the fourth keyword-only (CONTRIBUTING.md):\n" + "\n".join(found)
