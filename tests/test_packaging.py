"""The wheel carries the shaders and the model as package data, installs nothing generic at top level
and no training code (net/), and an installed wheel runs `glradial evaluate` from another folder with
torch and net made unimportable. Nothing in glradial/ imports torch or net.

The wheel is built from a copy of the tracked files in a temporary folder: setuptools writes its
``build/`` folder into the source tree it builds, and a copy inside the repository doubles every
search hit.
"""

from __future__ import annotations

import ast
import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Imports the probes make fail: the training code and its framework.
BLOCKED = ("torch", "net")

#: Prepended to a probe: a meta-path finder that makes ``import torch`` / ``import net`` raise.
BLOCKER = f"""
import importlib.abc, sys
class _Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {BLOCKED!r}:
            raise ImportError("blocked by the packaging test: " + name)
        return None
sys.meta_path.insert(0, _Blocker())
"""


def _source_files() -> list[str]:
    """Files of the source tree that a build may read: the files git does not ignore (a checkout),
    else all but the usual generated folders."""
    try:
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT, check=True, capture_output=True).stdout
        return [name for name in listed.decode().split("\0") if name and (ROOT / name).is_file()]
    except (OSError, subprocess.CalledProcessError):
        skip = {".git", ".venv", "build", "dist", "data_cache", "runs", "out"}
        return [str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file() and not skip & set(p.relative_to(ROOT).parts)]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    source = tmp_path_factory.mktemp("source")
    for name in _source_files():
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, source / name)
    out = tmp_path_factory.mktemp("wheel")
    had_build = (ROOT / "build").exists()
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", str(source), "-w", str(out)],
        check=True,
        capture_output=True,
    )
    assert (ROOT / "build").exists() == had_build, "the build wrote into the repository"
    (path,) = out.glob("glradial-*.whl")
    return path


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("site")
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
    )
    return target


def test_wheel_layout(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {name.split("/")[0] for name in names if not name.startswith("glradial-")}
    assert top_level == {"glradial"}, f"only glradial/ may be installed at top level, got {sorted(top_level)}"
    assert not [n for n in names if n.startswith(("glradial/net/", "net/"))], "training code must not ship"
    shipped_shaders = {Path(n).name for n in names if n.startswith("glradial/shaders/")}
    repo_shaders = {p.name for p in (ROOT / "shaders").iterdir() if p.suffix in {".glsl", ".vert", ".frag"}}
    assert repo_shaders <= shipped_shaders, f"missing from wheel: {sorted(repo_shaders - shipped_shaders)}"
    models = ROOT / "glradial" / "models"
    repo_models = {p.name for suffix in ("*.onnx", "*.sha256") for p in models.glob(suffix)}  # checksums too
    shipped_models = {Path(n).name for n in names if n.startswith("glradial/models/")}
    assert repo_models <= shipped_models
    shipped_modules = {n for n in names if n.startswith("glradial/") and n.endswith(".py")}
    repo_modules = {str(p.relative_to(ROOT)) for p in (ROOT / "glradial").rglob("*.py")}
    assert repo_modules == shipped_modules
    sub_packages = {p.parent.relative_to(ROOT).as_posix() for p in (ROOT / "glradial").glob("*/__init__.py")}
    shipped_packages = {Path(n).parent.as_posix() for n in names if n.endswith("/__init__.py")}
    assert "glradial/py.typed" in names, "py.typed must ship: type checkers read the exports"
    assert sub_packages and sub_packages <= shipped_packages, f"sub-packages missing from the wheel: {sorted(sub_packages - shipped_packages)}"


def test_installed_wheel_works_from_any_folder(installed, tmp_path):
    probe = BLOCKER + (
        "import glradial\n"
        "shader_dir = glradial.shader_dir\n"
        "assert str(shader_dir()).startswith(sys.argv[1]), shader_dir()\n"
        "assert (shader_dir() / 'common.glsl').read_text().strip() and glradial.shader_path('correct.frag').is_file()\n"
        "assert glradial.__file__.startswith(sys.argv[1]), glradial.__file__\n"
        "print(glradial.Lens(-0.2, 0.03).inverse_coefficients()[0])\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe, str(installed)],
        cwd=tmp_path,
        env={"PYTHONPATH": str(installed), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert float(result.stdout) == pytest.approx(0.2)


def test_installed_wheel_evaluates_without_torch(installed, tmp_path):
    """``glradial evaluate`` of the bundled model from the installed wheel, in a folder outside the
    checkout, with torch and net unimportable: a real (small) evaluation, and neither was loaded."""
    probe = BLOCKER + (
        "from glradial.cli import main\n"
        "status = main(sys.argv[2:])\n"
        "import glradial.evaluation.evaluation\n"
        "assert glradial.evaluation.evaluation.__file__.startswith(sys.argv[1]), glradial.evaluation.evaluation.__file__\n"
        "loaded = sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'net'))\n"
        "assert not loaded, loaded\n"
        "sys.exit(status)\n"
    )
    out = tmp_path / "eval"
    argv = ["evaluate", "--out", str(out), "--n", "4", "--test-panoramas", "1", "--panorama-size", "256x128",
            "--cache-dir", str(tmp_path / "cache"), "--threads", "1"]
    result = subprocess.run(
        [sys.executable, "-c", probe, str(installed), *argv],
        cwd=tmp_path,
        env={"PYTHONPATH": str(installed), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)},
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["overall"]["n"] == 4 and metrics["model"].startswith(str(installed))
    assert "no field panorama given" in result.stderr


def test_glradial_never_imports_torch_or_net():
    """Static check of every module under glradial/ (function-local imports included)."""
    offenders = []
    for path in sorted((ROOT / "glradial").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            offenders += [f"{path.relative_to(ROOT)}:{node.lineno} {n}" for n in names if n.split(".")[0] in BLOCKED]
    assert not offenders, offenders


def test_shader_dir_works_in_the_editable_install(tmp_path):
    """The checkout's own install (``make setup``: editable): ``glradial.shader_dir()`` from another
    folder finds the checkout's shaders/, the same files the wheel ships."""
    probe = "import glradial; d = glradial.shader_dir(); print(d); assert (d / 'common.glsl').is_file()"
    result = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()) == ROOT / "shaders"
