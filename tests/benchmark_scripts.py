"""Loading a script of benchmarks/ as a module, so tests can call its functions."""

import importlib.util
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def script_path(name: str) -> Path:
    """benchmarks/<name>.py."""
    return ROOT / "benchmarks" / f"{name}.py"


def load_script(name: str) -> ModuleType:
    """benchmarks/<name>.py imported as the module ``name`` (its ``main`` is not run)."""
    spec = importlib.util.spec_from_file_location(name, script_path(name))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
