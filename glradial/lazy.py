"""Lazy exports for glradial's packages: a package lists its public names once, as imports under
``if TYPE_CHECKING:`` (which type checkers read), and this module turns that list into a module
``__getattr__`` that imports the defining module on first use, so importing a package stays light."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path
from typing import Any, Callable


def _type_checking_imports(source: str) -> dict[str, str]:
    """``{public name: relative module}`` of the ``from .x import a, b`` lines under ``if TYPE_CHECKING:``."""
    exports: dict[str, str] = {}
    for node in ast.parse(source).body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for statement in node.body:
                if isinstance(statement, ast.ImportFrom) and statement.level == 1:
                    for alias in statement.names:
                        exports[alias.asname or alias.name] = "." + (statement.module or alias.name)
    return exports


def attach(package: str, init_file: str) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """``(__getattr__, __dir__, __all__)`` for the package whose ``__init__.py`` is ``init_file``."""
    exports = _type_checking_imports(Path(init_file).read_text(encoding="utf-8"))
    names = sorted(exports)

    def __getattr__(name: str) -> Any:
        module_name = exports.get(name)
        if module_name is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module = importlib.import_module(module_name, package)
        # ``from .x import x``-style module exports name the module itself
        value = module if module_name == "." + name else getattr(module, name)
        setattr(importlib.import_module(package), name, value)
        return value

    def __dir__() -> list[str]:
        return names

    return __getattr__, __dir__, names
