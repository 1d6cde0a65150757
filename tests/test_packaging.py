"""The wheel carries the shaders (and the model, once shipped) as package data, installs nothing generic
at top level, and `import glradial` works from another folder without importing torch."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", str(ROOT), "-w", str(out)],
        check=True,
        capture_output=True,
    )
    (path,) = out.glob("glradial-*.whl")
    return path


def test_wheel_layout(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {name.split("/")[0] for name in names if not name.startswith("glradial-")}
    assert top_level == {"glradial"}, f"only glradial/ may be installed at top level, got {sorted(top_level)}"
    shipped_shaders = {Path(n).name for n in names if n.startswith("glradial/shaders/")}
    repo_shaders = {p.name for p in (ROOT / "shaders").iterdir() if p.suffix in {".glsl", ".vert", ".frag"}}
    assert repo_shaders <= shipped_shaders, f"missing from wheel: {sorted(repo_shaders - shipped_shaders)}"
    models = ROOT / "glradial" / "models"
    repo_models = {p.name for suffix in ("*.onnx", "*.sha256") for p in models.glob(suffix)}  # checksums too
    shipped_models = {Path(n).name for n in names if n.startswith("glradial/models/")}
    assert repo_models <= shipped_models


def test_installed_wheel_works_from_any_folder(wheel, tmp_path):
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
    )
    probe = (
        "import sys, glradial\n"
        "from glradial.shaderlib import shader_dir\n"
        "assert str(shader_dir()).startswith(sys.argv[1]), shader_dir()\n"
        "assert 'torch' not in sys.modules\n"
        "print(glradial.Lens(-0.2, 0.03).inverse_coefficients()[0])\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe, str(target)],
        cwd=tmp_path,
        env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert float(result.stdout) == pytest.approx(0.2)
