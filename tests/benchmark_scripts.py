"""Loading a script of benchmarks/ as a module, so tests can call its functions."""

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

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
