"""Loads GLSL files from ``shaders/``: resolves ``#include``, injects ``#define``s, keeps ``#line``;
the texture formats of the image dtypes the programs read and write (:data:`TEXTURE_FORMATS`).

Shaders are files, shipped as package data (``glradial/shaders`` in a wheel, ``shaders/`` at the top
of a source checkout). A program is built from a vertex and a fragment file; every file gets a
source-string number in ``#line`` directives so that a compile error reported by the driver as
``3:17(5): error ...`` is rewritten to ``common.glsl:17: error ...``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import moderngl
import numpy as np

from ..errors import ShaderCompileError

GLSL_VERSION = "330 core"
#: NumPy dtype of an image -> (moderngl texture dtype, the sample value a shader reads as 1.0), for
#: the textures the programs sample and the framebuffers they write (uint8/uint16 normalised).
TEXTURE_FORMATS = {
    np.dtype(np.uint8): ("f1", 255.0),
    np.dtype(np.uint16): ("nu2", 65535.0),
    np.dtype(np.float32): ("f4", 1.0),
}
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')
_ERROR_LOCATION = re.compile(r"\b(\d+):(\d+)(\(\d+\))?")


def shader_dir() -> Path:
    """The folder holding glradial's GLSL files (public: ``glradial.shader_dir()``), for embedding
    them in another renderer: ``common.glsl`` (the lens functions), ``sampling.glsl``,
    ``correct.frag``, ``distort.frag`` ... (docs/SHADERS.md). Package data in an installed wheel,
    the checkout's ``shaders/`` in the editable install ``make setup`` makes (where
    ``importlib.resources.files("glradial.shaders")`` cannot find them).

    Args:
        None.

    Returns:
        The folder (an absolute :class:`pathlib.Path`).

    Raises:
        FileNotFoundError: neither place holds ``common.glsl`` (a broken install).

    Example:
        >>> import glradial
        >>> (glradial.shader_dir() / "common.glsl").is_file()
        True
    """
    here = Path(__file__).resolve().parents[1]  # the glradial package
    for candidate in (here / "shaders", here.parent / "shaders"):
        if (candidate / "common.glsl").is_file():
            return candidate
    raise FileNotFoundError(
        f"glradial's GLSL files are missing: looked for common.glsl in {here / 'shaders'} and "
        f"{here.parent / 'shaders'}; reinstall the package"
    )


def shader_path(name: str) -> Path:
    """Path of one of glradial's shader files by name.

    Args:
        name: the file name inside :func:`shader_dir` (e.g. ``"common.glsl"``, ``"correct.frag"``).

    Returns:
        The file's absolute path.

    Raises:
        FileNotFoundError: no shader of that name (or the shader folder is missing).

    Example:
        >>> import glradial
        >>> glradial.shader_path("common.glsl").name
        'common.glsl'
        >>> "distort" in glradial.shader_path("common.glsl").read_text()
        True
    """
    path = shader_dir() / name
    if not path.is_file():
        raise FileNotFoundError(f"no shader named {name!r} in {shader_dir()}")
    return path


@dataclass
class ShaderSource:
    """A preprocessed GLSL source plus the table that maps source-string numbers to file names."""

    text: str
    files: list[str] = field(default_factory=list)

    def explain(self, driver_log: str) -> str:
        """Rewrite ``N:LINE(COL)`` locations of a driver log into ``file:LINE``."""

        def rename(match: re.Match) -> str:
            index, line = int(match.group(1)), match.group(2)
            if index < len(self.files):
                return f"{self.files[index]}:{line}"
            return match.group(0)

        return _ERROR_LOCATION.sub(rename, driver_log)


def preprocess(name: str, defines: Mapping[str, object] | None = None) -> ShaderSource:
    """Read shader ``name`` with its includes expanded and ``defines`` injected after ``#version``.

    ``defines`` maps macro names to values written with ``str()`` (``True``/``False`` become 1/0).
    Each include is guarded so that a file included twice is inserted once.
    """
    files: list[str] = []
    included: set[str] = set()

    def expand(file_name: str) -> list[str]:
        index = len(files)
        files.append(file_name)
        included.add(file_name)
        out = [f"#line 1 {index}"]
        for number, line in enumerate(shader_path(file_name).read_text().splitlines(), start=1):
            match = _INCLUDE.match(line)
            if match:
                child = match.group(1)
                if child not in included:
                    out += expand(child)
                out.append(f"#line {number + 1} {index}")
            elif line.lstrip().startswith("#version"):
                out.append("")  # the loader writes the one #version line
            else:
                out.append(line)
        return out

    header = [f"#version {GLSL_VERSION}"]
    for key, value in (defines or {}).items():
        if isinstance(value, bool):
            value = int(value)
        header.append(f"#define {key} {value}")
    body = expand(name)
    return ShaderSource("\n".join(header + body) + "\n", files)


def build_program(
    ctx: moderngl.Context,
    vertex: str,
    fragment: str,
    defines: Mapping[str, object] | None = None,
) -> moderngl.Program:
    """Compile and link ``vertex`` + ``fragment`` (file names in ``shaders/``) with ``defines``.

    Raises :class:`ShaderCompileError` whose message names the file and line of each error.
    """
    vs = preprocess(vertex, defines)
    fs = preprocess(fragment, defines)
    try:
        return ctx.program(vertex_shader=vs.text, fragment_shader=fs.text)
    except Exception as err:  # moderngl raises a bare Exception carrying the driver log
        log = str(err)
        explained = fs.explain(log) if "fragment" in log.lower() else vs.explain(log)
        raise ShaderCompileError(f"GLSL program {vertex} + {fragment} failed:\n{explained}") from None
