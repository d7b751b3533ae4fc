"""A package's public names imported on first use (PEP 562), so importing the package stays light.

A package's ``__init__`` says where each name lives::

    __all__, __getattr__, __dir__ = lazy_exports(__name__, {"TrainConfig": "training", "load_agent": "checkpoints"})

The command line builds its help from light modules of such packages without importing
torch, scikit-learn or pybullet; ``from package import TrainConfig`` still works.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


class LazyExports:
    """The public names of a package, each imported from its module when first asked for.

    Args:
        package: the package's name (its ``__name__``).
        exports: each public name, and the module (relative to the package) that defines it.
    """

    def __init__(self, package: str, exports: Mapping[str, str]) -> None:
        self.package = package
        self.exports = dict(exports)

    @property
    def names(self) -> list[str]:
        """The public names, sorted (the package's ``__all__``)."""
        return sorted(self.exports)

    def load(self, name: str) -> Any:
        """Import ``name`` from its module, and keep it in the package (later lookups skip this).

        Raises:
            AttributeError: the package has no such name.
        """
        if name not in self.exports:
            raise AttributeError(f"module {self.package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{self.package}.{self.exports[name]}"), name)
        setattr(sys.modules[self.package], name, value)
        return value

    def dir(self) -> list[str]:
        """The package's attributes and its public names (the package's ``__dir__``)."""
        return sorted(set(vars(sys.modules[self.package])) | set(self.exports))


def lazy_exports(package: str, exports: Mapping[str, str]) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """A package's ``__all__``, ``__getattr__`` and ``__dir__`` for the names of ``exports`` (see :class:`LazyExports`)."""
    lazy = LazyExports(package, exports)
    return lazy.names, lazy.load, lazy.dir
