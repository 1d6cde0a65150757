"""The package's shape holds: sub-packages in a declared layer order (no import runs upward, none
in a circle), no circle between modules (imports inside functions included) in glradial/ or net/,
no private name imported from another module, no function over 60 lines of code in glradial/,
net/, bench/ or scripts/, the public names the README and docs use import, and ruff finds nothing. All read the source
with ``ast`` (nothing is imported except in the public-names test)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "glradial"
#: the training package (a source checkout's, not the wheel's): the module rules hold there too
NET = ROOT / "net"

#: The layers, lowest first: a unit may import from its own layer and the ones before it. Units are
#: the top-level modules and the sub-packages; ``__init__`` (the lazy public API) is the top.
LAYERS = ["errors", "lazy", "threads", "schemas", "lens", "gl", "media", "remapping", "export", "pitch", "synthesis", "estimation", "camera", "video",
          "tracking", "evaluation", "commands", "jobs", "cli", "__main__", "__init__"]
#: Folders under glradial/ that hold data, not code.
DATA = {"data", "models", "__pycache__"}
MAX_FUNCTION_LINES = 60
MAX_TOP_LEVEL_MODULES = 8
MAX_MODULES_PER_PACKAGE = 12
#: commands/ holds one module per subcommand (the CLI grows with them) and at most this many shared
#: modules beside them (modules that define no ``add_parser``).
MAX_SHARED_COMMAND_MODULES = 3


def _sources() -> list[Path]:
    return _modules(PACKAGE)


def _unit(path: Path) -> str:
    """The layer unit of a file: its sub-package, or its module name at top level."""
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else parts[0][:-3]


def _imports(path: Path) -> list[tuple[str, list[str], int]]:
    """``(absolute module, imported names, line)`` of every glradial import in ``path`` (also inside
    functions), resolved from relative form."""
    package = ["glradial", *path.relative_to(PACKAGE).parts[:-1]]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module == "glradial" or module.startswith("glradial."):
                found.append((module, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("glradial."):
                    found.append((alias.name, [], node.lineno))
    return found


def _target_units(module: str, names: list[str]) -> list[tuple[str, str]]:
    """``(unit, dotted path inside glradial)`` an import reaches: ``from glradial import x`` of a
    sub-package or module reaches that unit."""
    parts = module.split(".")[1:]
    if not parts and all(name.startswith("__") for name in names):
        return []  # ``from glradial import __version__``: a constant set before anything else
    if parts:
        return [(parts[0], ".".join(parts))]
    return [(name, name) for name in names if (PACKAGE / name).is_dir() or (PACKAGE / f"{name}.py").is_file()] or [("__init__", "")]


def _edges():
    """``(file, its unit, imported module, imported names, line, target unit, dotted target)`` of every
    glradial import in the package."""
    for path in _sources():
        mine = _unit(path)
        for module, names, line in _imports(path):
            for unit, dotted in _target_units(module, names):
                yield path, mine, module, names, line, unit, dotted


def test_layers_cover_the_package():
    units = {_unit(p) for p in _sources()}
    assert units == set(LAYERS), f"declare each unit's layer: missing {sorted(units - set(LAYERS))}, stale {sorted(set(LAYERS) - units)}"


def test_no_import_runs_upward():
    upward = [f"{path.relative_to(ROOT)}:{line} ({mine}) imports {module} ({unit})"
              for path, mine, module, _, line, unit, _ in _edges() if unit in LAYERS and LAYERS.index(unit) > LAYERS.index(mine)]
    assert not upward, "imports that run up the layers:\n" + "\n".join(upward)


def test_no_circle_between_sub_packages():
    graph: dict[str, set[str]] = {}
    for _, mine, _, _, _, unit, _ in _edges():
        if unit != mine and mine != "__init__":
            graph.setdefault(mine, set()).add(unit)
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            assert state.get(nxt) != 1, "import circle: " + " -> ".join(trail + [node, nxt])
            if nxt not in state:
                visit(nxt, trail + [node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])


def test_no_private_name_imported_across_sub_packages():
    leaks = []
    for path, mine, module, names, line, unit, dotted in _edges():
        private = [p for p in dotted.split(".") + names if p.startswith("_") and not p.startswith("__")]
        if unit != mine and private:
            leaks.append(f"{path.relative_to(ROOT)}:{line} imports {', '.join(private)} from {module}")
    assert not leaks, "private names used outside their sub-package:\n" + "\n".join(leaks)


def test_sizes():
    top = [p.name for p in PACKAGE.glob("*.py")]
    assert len(top) <= MAX_TOP_LEVEL_MODULES, sorted(top)
    for folder in PACKAGE.iterdir():
        if folder.is_dir() and folder.name not in DATA:
            modules = [p.name for p in folder.glob("*.py") if p.name != "__init__.py"]
            assert (folder / "__init__.py").is_file(), folder
            if folder.name == "commands":
                shared = [m for m in modules if "def add_parser" not in (folder / m).read_text(encoding="utf-8")]
                assert len(shared) <= MAX_SHARED_COMMAND_MODULES, sorted(shared)
            else:
                assert len(modules) <= MAX_MODULES_PER_PACKAGE, (folder.name, sorted(modules))
            doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text(encoding="utf-8")))
            assert doc, f"{folder.name}/__init__.py must say what the sub-package owns"


def _code_lines(node: ast.AST, lines: list[str]) -> int:
    """Lines of code of a function: its lines less its docstring, blank lines and comment lines."""
    skip: set[int] = set()
    first = node.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        skip = set(range(first.lineno, first.end_lineno + 1))
    return sum(1 for i in range(node.lineno, node.end_lineno + 1)
               if i not in skip and lines[i - 1].strip() and not lines[i - 1].strip().startswith("#"))


def _long_functions(paths: list[Path]) -> list[str]:
    long = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = _code_lines(node, lines)
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {n} lines")
    return long


@pytest.mark.parametrize("package", [PACKAGE, NET, ROOT / "bench", ROOT / "scripts"], ids=["glradial", "net", "bench", "scripts"])
def test_no_function_over_60_lines(package: Path):
    long = _long_functions(_modules(package))
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines of code:\n" + "\n".join(long)


# -- modules ------------------------------------------------------------------------------------
def _modules(package: Path) -> list[Path]:
    """The Python files of ``package`` (glradial/ or net/), data folders left out."""
    return sorted(p for p in package.rglob("*.py") if p.relative_to(package).parts[0] not in DATA)


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _runtime_nodes(tree: ast.AST):
    """Every node of ``tree`` that runs (in functions too), less the bodies of ``if TYPE_CHECKING:``."""
    stack = [tree]
    while stack:
        for child in ast.iter_child_nodes(stack.pop()):
            if isinstance(child, ast.If) and getattr(child.test, "id", "") == "TYPE_CHECKING":
                stack.extend(child.orelse)
                continue
            yield child
            stack.append(child)


def _module_imports(package: Path) -> list[tuple[str, str, list[str], int]]:
    """``(importing module, imported module, imported names, line)`` of every import inside
    ``package``, resolved to the module that defines what is imported: ``from pkg import mod`` reaches
    ``pkg.mod``, and a package's lazy export (``glradial.lazy``) reaches the module it names."""
    paths = {_module_name(p): p for p in _modules(package)}
    lazy = {}
    for name, path in paths.items():
        if path.name == "__init__.py":
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
                    for statement in node.body:
                        if isinstance(statement, ast.ImportFrom) and statement.level == 1:
                            for alias in statement.names:
                                lazy[(name, alias.asname or alias.name)] = f"{name}.{statement.module}"
    found = []
    for mine, path in paths.items():
        here = mine.split(".") if path.name == "__init__.py" else mine.split(".")[:-1]
        for node in _runtime_nodes(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                base = here[: len(here) - node.level + 1] if node.level else []
                module = ".".join(base + ([node.module] if node.module else []))
                if module.split(".")[0] != package.name:
                    continue
                for alias in node.names:
                    target = f"{module}.{alias.name}"
                    target = target if target in paths else lazy.get((module, alias.name), module)
                    found.append((mine, target, [alias.name], node.lineno))
            elif isinstance(node, ast.Import):
                found += [(mine, alias.name, [], node.lineno) for alias in node.names if alias.name.split(".")[0] == package.name]
    return found


@pytest.mark.parametrize("package", [PACKAGE, NET], ids=["glradial", "net"])
def test_no_circle_between_modules(package: Path):
    """No module imports, directly or through others, a module that imports it (function-level
    imports count: they only hide a circle until the function runs)."""
    graph: dict[str, set[str]] = {}
    for mine, target, _, _ in _module_imports(package):
        if target != mine:
            graph.setdefault(mine, set()).add(target)
    state: dict[str, int] = {}
    circles = []

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                circles.append(" -> ".join(trail[trail.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, trail + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not circles, "import circles between modules:\n" + "\n".join(circles)


@pytest.mark.parametrize("package", [PACKAGE, NET], ids=["glradial", "net"])
def test_no_private_name_imported_across_modules(package: Path):
    leaks = [f"{mine}:{line} imports {name} from {target}" for mine, target, names, line in _module_imports(package)
             for name in names if name.startswith("_") and not name.startswith("__") and target != mine]
    assert not leaks, "private names used outside their module (make a shared name public):\n" + "\n".join(leaks)


#: Public names the README and docs use, beyond those found by pattern below.
PUBLIC = ["correct", "distort", "estimate", "fit_scale", "Lens", "LensEstimate", "Estimator", "Remapper", "render_crops",
          "CropParams", "CropRenderer", "sample_crop_params", "crop_batches", "stadium_panorama", "StadiumRenderer",
          "Error", "GLUnavailableError", "ShaderCompileError", "ModelLoadError", "LensTrackError", "__version__"]


def test_public_names_import():
    import glradial

    used = set(PUBLIC)
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        used |= set(re.findall(r"\bglradial\.([A-Za-z_]\w*)\b(?!\.py|/)", doc.read_text(encoding="utf-8")))
    modules = {p.name for p in PACKAGE.iterdir() if p.is_dir()} | {p.stem for p in PACKAGE.glob("*.py")} | {"shaders"}
    missing = [name for name in sorted(used - modules) if not hasattr(glradial, name)]
    assert not missing, f"names the docs use that glradial does not export: {missing}"
    assert set(PUBLIC) - {"__version__"} <= set(glradial.__all__)
    for name in glradial.__all__:
        getattr(glradial, name)
    from glradial.lens import Lens

    assert Lens is glradial.Lens


def test_type_checkers_see_every_export():
    """Every lazily exported name of each package is imported under ``TYPE_CHECKING``."""
    for init in [PACKAGE / "__init__.py", *sorted(PACKAGE.glob("*/__init__.py"))]:
        tree = ast.parse(init.read_text(encoding="utf-8"))
        guarded = [n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", "") == "TYPE_CHECKING"]
        if init.parent.name in DATA or "attach(" not in init.read_text(encoding="utf-8"):
            continue
        assert guarded, f"{init.relative_to(ROOT)}: no TYPE_CHECKING imports"


def test_ruff_finds_nothing():
    pytest.importorskip("ruff")
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "glradial", "net", "tests", "bench"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr


def test_module_names_are_unique():
    """A module's file name says where it lives: no two modules of glradial/ share one (``__init__``
    aside; commands/ mirrors the subcommands, so its modules may repeat a name found elsewhere)."""
    seen: dict[str, list[str]] = {}
    for path in _sources():
        relative = path.relative_to(PACKAGE)
        if path.name != "__init__.py" and relative.parts[0] != "commands":
            seen.setdefault(path.name, []).append(relative.as_posix())
    twice = {name: where for name, where in seen.items() if len(where) > 1}
    assert not twice, f"module names used twice in glradial/: {twice}"


def test_public_class_names_are_unique():
    """One public class per name across glradial/ (a second ``Camera`` or ``Estimator`` is a second
    concept under the same word)."""
    seen: dict[str, list[str]] = {}
    for path in _sources():
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                seen.setdefault(node.name, []).append(path.relative_to(PACKAGE).as_posix())
    twice = {name: where for name, where in seen.items() if len(where) > 1}
    assert not twice, f"public classes defined twice: {twice}"


def test_tests_mirror_the_package():
    """tests/ holds one folder per glradial sub-package (plus net/ and bench/, the checkout's other
    code); project-wide tests (layout, docs, packaging) stay at its top."""
    packages = {p.parent.name for p in PACKAGE.glob("*/__init__.py")} | {"net", "bench"}
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and p.name not in {"data", "__pycache__"}}
    assert folders <= packages, f"test folders that mirror no package: {sorted(folders - packages)}"
    assert len(folders) >= 10, folders
