"""Loading a script of benchmarks/ as a module (tests call its functions), or running it in this process (tests check its flags)."""

import argparse
import contextlib
import importlib.util
import io
import os
import runpy
import signal
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, NoReturn
from unittest import mock

ROOT = Path(__file__).resolve().parents[1]


def script_path(name: str) -> Path:
    """benchmarks/<name>.py."""
    return ROOT / "benchmarks" / f"{name}.py"


def load_script(name: str) -> ModuleType:
    """benchmarks/<name>.py imported as the module ``name`` (its ``main`` is not run). The
    scripts import each other as a script run from benchmarks/ does, so that folder goes on
    the import path. The module is registered in ``sys.modules`` before it runs, as an import
    would register it (a dataclass looks its module up there)."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location(name, script_path(name))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]  # as importlib leaves no half-loaded module behind
        raise
    return module


@dataclass(frozen=True)
class ScriptRun:
    """What a script run by :func:`run_script` returned and printed (as a CompletedProcess holds them)."""

    returncode: int
    stdout: str
    stderr: str


class _Parsed(Exception):
    """Raised by :func:`run_script` with ``parse_only`` once the script's flags have parsed."""


_PARSE_ARGS = argparse.ArgumentParser.parse_args


def _parse_then_stop(parser: argparse.ArgumentParser, args: Sequence[str] | None = None, namespace: Any = None) -> NoReturn:
    _PARSE_ARGS(parser, args, namespace)  # a refused flag exits 2 here, as on the command line
    parser.format_help()  # and --help must print: a lone % in a help string breaks it
    raise _Parsed


def _too_long(signum: int, frame: Any) -> NoReturn:
    raise TimeoutError("the script ran past run_script's timeout_s (a refusal that no longer refuses runs the whole benchmark)")


def run_script(path: Path, *arguments: str, parse_only: bool = False, timeout_s: float = 120.0) -> ScriptRun:
    """Run the script ``path`` as ``python path ARGUMENTS`` from the project's root would, but in
    this process: a new Python process spends about 6 s importing torch, PyBullet and
    Gymnasium before the script parses its first flag. For flags a script refuses, or its
    ``--help``; a run that does the work is better run in a process of its own.

    The script runs as ``__main__`` with ``sys.argv``, the current folder and the import path
    a command line would give it; all three are restored afterwards. Its exit code is 0 when
    it returns, else what it passed to ``sys.exit`` (1 for a message, as Python exits).
    With ``parse_only`` the script stops, with exit code 0, once its parser has taken every
    flag: an unknown flag, a missing one or a value of the wrong type exits 2 as on the
    command line (``--help`` would not catch an unknown flag: argparse prints the help and
    exits before it looks at what it did not know), and its help is formatted too.

    What this cannot check, a test runs once in a fresh interpreter: that every script
    imports with only benchmarks/ on the import path (here tests/ is on it too).

    Raises:
        TimeoutError: the script ran longer than ``timeout_s`` seconds (checked with a
            timer signal, so only in the main thread, as pytest runs tests).
    """
    out, err = io.StringIO(), io.StringIO()
    argv, cwd = sys.argv, Path.cwd()
    sys.argv = [str(path), *arguments]
    sys.path.insert(0, str(path.parent))
    os.chdir(ROOT)
    previous = signal.signal(signal.SIGALRM, _too_long)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        stop = mock.patch.object(argparse.ArgumentParser, "parse_args", _parse_then_stop) if parse_only else contextlib.nullcontext()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), stop:
            runpy.run_path(str(path), run_name="__main__")
        code = 0
    except _Parsed:
        code = 0
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        if isinstance(exit_.code, str):
            err.write(exit_.code + "\n")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
        sys.argv = argv
        sys.path.remove(str(path.parent))
        os.chdir(cwd)
    return ScriptRun(code, out.getvalue(), err.getvalue())
