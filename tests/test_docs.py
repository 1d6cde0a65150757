"""The user documentation keeps up with the code: every option of every subcommand is in
docs/CLI.md (each subcommand with a section of its own), every ``glradial ...`` command line the
README and docs/CLI.md / docs/CAMERA.md show parses with the real parser (option names, choices,
value types), and every name ``glradial`` exports is in the README. The oracle is the argparse
parser and ``glradial.__all__`` themselves, so an option or export added without its doc fails here."""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

import glradial
from glradial.cli import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parent.parent
CLI_DOC = ROOT / "docs" / "CLI.md"
SHOWN = [ROOT / "README.md", CLI_DOC, ROOT / "docs" / "CAMERA.md"]


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _mentioned(option: str, text: str) -> bool:
    return re.search(re.escape(option) + r"(?![\w-])", text) is not None


@pytest.mark.parametrize("command", COMMANDS)
def test_every_option_of_every_subcommand_is_in_cli_md(command):
    text = CLI_DOC.read_text(encoding="utf-8")
    assert re.search(rf"^## `?{command}\b", text, re.M), f"docs/CLI.md has no '## {command}' section"
    options = [s for a in _subparsers()[command]._actions for s in a.option_strings if s.startswith("--") and s != "--help"]
    missing = [o for o in options if not _mentioned(o, text)]
    assert not missing, f"glradial {command}: options missing from docs/CLI.md: {missing}"


def _shown_command_lines() -> list[tuple[str, str, str]]:
    """(file, subcommand, the rest of the line) for each ``glradial SUB ...`` in a code block."""
    found = []
    for path in SHOWN:
        for block in re.findall(r"```[a-z]*\n(.*?)```", path.read_text(encoding="utf-8"), re.S):
            for line in block.splitlines():
                match = re.search(r"(?:^|\|\s*)glradial (\w+)(?= |$)(.*)", line.strip())
                if match and match.group(1) in COMMANDS:
                    rest = re.split(r"\s#\s|\s\|\s|\s>\s|\s<\s", match.group(2))[0]  # comments, pipes, redirections
                    found.append((path.name, match.group(1), rest))
    return found


def test_the_docs_show_command_lines():
    shown = {command for _, command, _ in _shown_command_lines()}
    assert {"correct", "distort", "estimate", "calibrate", "stmap", "live", "crops", "stadium"} <= shown, shown


@pytest.mark.parametrize("where,command,rest", _shown_command_lines())
def test_every_shown_command_line_parses(where, command, rest):
    options = {s for a in _subparsers()[command]._actions for s in a.option_strings}
    named = re.findall(r"(?<![\w/.-])(--?[a-zA-Z][\w-]*)", rest)
    unknown = [o for o in named if o not in options]
    assert not unknown, f"{where}: 'glradial {command}{rest}' names options it does not have: {unknown}"
    if re.search(r"[\[\]|…]|\.\.\.|\\$", rest):
        return  # a synopsis ([--opt], a|b, ...): the names are checked, not the values
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr):
            build_parser().parse_args([command, *shlex.split(rest)])
    except SystemExit:
        pytest.fail(f"{where}: 'glradial {command}{rest}' does not parse: {stderr.getvalue().strip()}")


def test_the_parser_check_catches_a_wrong_option():
    """The check above can fail: a misspelt option and a bad choice are refused by the parser."""
    for argv in (["stmap", "--k1", "-0.2", "--size", "64x36", "--out", "x.exr", "--layot", "unreal"],
                 ["stmap", "--k1", "-0.2", "--size", "64x36", "--out", "x.exr", "--layout", "maya"]):
        with contextlib.redirect_stderr(io.StringIO()), pytest.raises(SystemExit):
            build_parser().parse_args(argv)


def test_every_public_name_is_in_the_readme():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    missing = [name for name in glradial.__all__ if not re.search(rf"`[^`]*\b{re.escape(name)}\b[^`]*`", readme)]
    assert not missing, f"exported by glradial but not in README.md: {missing}"


def test_every_file_the_docs_name_exists():
    """Links and `path/like/this.py` mentions in README.md and docs/*.md point at files that exist
    (a renamed or removed module, script or figure leaves a dead reference otherwise)."""
    dead = []
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = doc.read_text(encoding="utf-8")
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
            if "://" not in target and not (doc.parent / target).exists():
                dead.append(f"{doc.name}: link {target}")
        for path in re.findall(r"`((?:bench|scripts|tests|glradial|net|docs|examples|shaders)/[\w/.-]+\.[a-z]+)`", text):
            if not (ROOT / path).exists():
                dead.append(f"{doc.name}: {path}")
    assert not dead, "the docs name files that do not exist:\n" + "\n".join(dead)


def test_every_sub_package_is_in_the_readme_and_the_architecture_map():
    packages = sorted(p.parent.name for p in (ROOT / "glradial").glob("*/__init__.py") if p.parent.name not in {"data", "models"})
    assert "camera" in packages and "lens" in packages, packages
    for doc in (ROOT / "README.md", ROOT / "docs" / "ARCHITECTURE.md"):
        text = doc.read_text(encoding="utf-8")
        missing = [name for name in packages if not re.search(rf"(?<![\w/]){name}/", text)]
        assert not missing, f"{doc.name} does not name the sub-package(s) {missing}"
