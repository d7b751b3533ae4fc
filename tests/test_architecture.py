"""The package's layout holds its design: imports run one way, no file or folder grows too big.

Read statically with :mod:`ast` (nothing is imported), over every module of ``dvrk_gym``:

- nothing outside ``dvrk_gym/cli`` imports the command line;
- the layers import one way: a module imports only modules of its own layer or a lower one
  (``LAYER_RANKS``; ARCHITECTURE.md says what each layer holds);
- no module outside ``cli/`` imports a ``dvrk_gym`` module inside a function or method, the
  way to hide an import cycle (``import dvrk_gym`` at a module's top, to register the envs, is fine);
- no module over ``MAX_MODULE_LINES`` lines, no folder with more than ``MAX_FOLDER_MODULES``
  modules (``__init__.py`` counted).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dvrk_gym"
MAX_MODULE_LINES = 400
MAX_FOLDER_MODULES = 10

# Rank of each layer: a module may import modules of its own rank or lower. A key names a
# module or a package and everything under it; the longest matching key wins.
LAYER_RANKS = {
    "dvrk_gym.paper": 0,
    "dvrk_gym.utils": 0,
    "dvrk_gym.parallel": 0,
    "dvrk_gym.sim.physics": 1,
    "dvrk_gym.sim.identified": 1,
    "dvrk_gym.sim.robot": 2,
    "dvrk_gym.sim.compiled": 2,
    "dvrk_gym.sim.endoscope": 3,
    "dvrk_gym.sim.world": 4,
    "dvrk_gym.sim.world_config": 4,
    "dvrk_gym.sim.table": 5,
    "dvrk_gym.envs": 6,
    "dvrk_gym.demo": 6,
    "dvrk_gym.evaluation": 7,
    "dvrk_gym.calibration": 8,
    "dvrk_gym.fidelity": 8,
    "dvrk_gym.baselines": 9,
    "dvrk_gym.reproduce": 10,
    "dvrk_gym.sweep": 10,
    "dvrk_gym.cli": 11,
    "dvrk_gym.__main__": 11,
}
# Package faces, ranked by what they may re-export: ``dvrk_gym`` itself registers the envs
# and exports the public API of every layer below the CLI; ``dvrk_gym.sim`` may re-export all of sim/.
# These ranks apply only to the package's own ``__init__`` and to importing it by that name.
FACE_RANKS = {"dvrk_gym": LAYER_RANKS["dvrk_gym.reproduce"], "dvrk_gym.sim": LAYER_RANKS["dvrk_gym.sim.table"]}
CLI = "dvrk_gym.cli"
MAIN = "dvrk_gym.__main__"


@dataclass(frozen=True)
class Import:
    """One import statement's target in a module of dvrk_gym."""

    module: str  # the importing module
    target: str  # the dvrk_gym module imported (or the package a name is taken from)
    line: int
    in_function: bool

    def __str__(self) -> str:
        return f"{module_path(self.module)}:{self.line} imports {self.target}"


def module_name(path: Path) -> str:
    """``dvrk_gym/sim/world.py`` -> ``dvrk_gym.sim.world``; a package's ``__init__`` -> the package."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_path(name: str) -> str:
    """The file of a module of dvrk_gym, relative to the project root."""
    return str(MODULES[name].relative_to(ROOT))


MODULES = {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _absolute(module: str, node: ast.ImportFrom) -> str:
    """The absolute module named by a ``from ... import`` (relative ones resolved against ``module``)."""
    if node.level == 0:
        return node.module or ""
    package = module.split(".") if _is_package(module) else module.split(".")[:-1]
    base = package[: len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> list[str]:
    """The dvrk_gym modules an import statement reaches (``from pkg import sub`` reaches ``pkg.sub``)."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        source = _absolute(module, node)
        names = [f"{source}.{alias.name}" if f"{source}.{alias.name}" in MODULES else source for alias in node.names]
    return sorted({name for name in names if name == "dvrk_gym" or name.startswith("dvrk_gym.")})


def _walk(module: str, node: ast.AST, in_function: bool) -> list[Import]:
    found = []
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            found += [Import(module, target, child.lineno, in_function) for target in _targets(module, child)]
        inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        found += _walk(module, child, inside)
    return found


@cache
def imports_of(module: str) -> tuple[Import, ...]:
    """Every import of a dvrk_gym module in ``module``, at any depth, in source order."""
    tree = ast.parse(MODULES[module].read_text(), filename=str(MODULES[module]))
    return tuple(sorted(_walk(module, tree, in_function=False), key=lambda imp: imp.line))


def all_imports() -> list[Import]:
    return [imp for module in MODULES for imp in imports_of(module)]


def rank(module: str) -> int | None:
    """The layer rank of a module of dvrk_gym, or None if no layer claims it."""
    if module in FACE_RANKS:
        return FACE_RANKS[module]
    parts = module.split(".")
    for end in range(len(parts), 0, -1):
        prefix = ".".join(parts[:end])
        if prefix in LAYER_RANKS:
            return LAYER_RANKS[prefix]
    return None


def _in_cli(module: str) -> bool:
    """dvrk_gym/cli/, and ``python -m dvrk_gym``'s ``__main__``, which only runs it."""
    return module in (CLI, MAIN) or module.startswith(CLI + ".")


def _listing(offenders: list[str]) -> str:
    return "\n  " + "\n  ".join(offenders)


def test_every_module_belongs_to_a_layer():
    unranked = [module_path(module) for module in MODULES if rank(module) is None]
    assert not unranked, f"modules that no layer claims (add them to LAYER_RANKS and ARCHITECTURE.md):{_listing(unranked)}"


def test_nothing_outside_cli_imports_the_command_line():
    offenders = [str(imp) for imp in all_imports() if _in_cli(imp.target) and not _in_cli(imp.module)]
    assert not offenders, f"the command line is imported from outside dvrk_gym/cli:{_listing(offenders)}"


def test_layers_import_only_their_own_layer_or_lower_ones():
    offenders = []
    for imp in all_imports():
        own, target = rank(imp.module), rank(imp.target)
        if own is not None and target is not None and target > own:
            offenders.append(f"{imp} (layer {target} above its own layer {own})")
    assert not offenders, f"imports that go up the layers (see ARCHITECTURE.md):{_listing(offenders)}"


def test_no_dvrk_gym_import_inside_a_function_outside_cli():
    offenders = [str(imp) for imp in all_imports() if imp.in_function and not _in_cli(imp.module)]
    assert not offenders, f"dvrk_gym imports inside a function or method (move them to the module's top):{_listing(offenders)}"


def test_no_module_over_the_line_limit():
    lengths = {module_path(module): len(path.read_text().splitlines()) for module, path in MODULES.items()}
    offenders = [f"{path}: {n} lines" for path, n in sorted(lengths.items()) if n > MAX_MODULE_LINES]
    assert not offenders, f"modules over {MAX_MODULE_LINES} lines:{_listing(offenders)}"


def test_no_folder_over_the_module_limit():
    folders = sorted({path.parent for path in MODULES.values()})
    counts = {folder: len(list(folder.glob("*.py"))) for folder in folders}
    offenders = [f"{folder.relative_to(ROOT)}: {n} modules" for folder, n in counts.items() if n > MAX_FOLDER_MODULES]
    assert not offenders, f"folders with more than {MAX_FOLDER_MODULES} modules (__init__.py counted):{_listing(offenders)}"


# The checker checks itself: on small sources, what it must see and what it must not.


def test_relative_imports_resolve_against_the_importing_module():
    node = ast.parse("from ..robot import kinematics").body[0]
    assert isinstance(node, ast.ImportFrom)
    assert _absolute("dvrk_gym.sim.world", node) == "dvrk_gym.robot"
    assert _absolute("dvrk_gym.sim.table.grasp", node) == "dvrk_gym.sim.robot"
    assert _targets("dvrk_gym.sim.table.grasp", node) == ["dvrk_gym.sim.robot.kinematics"]
    package_node = ast.parse("from .robot import kinematics").body[0]
    assert isinstance(package_node, ast.ImportFrom)
    assert _absolute("dvrk_gym.sim", package_node) == "dvrk_gym.sim.robot"


def test_imports_inside_functions_and_methods_are_told_apart():
    source = "import dvrk_gym\nimport numpy\n\nclass A:\n    def f(self):\n        from dvrk_gym.cli import main\n"
    found = _walk("dvrk_gym.envs.base", ast.parse(source), in_function=False)
    assert [(imp.target, imp.in_function) for imp in found] == [("dvrk_gym", False), ("dvrk_gym.cli.main", True)]


def test_ranks_follow_the_longest_key_and_the_faces():
    assert rank("dvrk_gym.sim.robot.kinematics") == 2
    assert rank("dvrk_gym.sim.world") == 4
    assert rank("dvrk_gym") == 10 and rank("dvrk_gym.sim") == 5
    assert rank("dvrk_gym.cli.main") == 11
    assert rank("dvrk_gym.somewhere_new") is None
