"""Every public name of ``glradial`` documents its Args / Returns / Raises and carries an example
that runs (the same examples ``pytest --doctest-modules glradial`` runs in ``make test``)."""

from __future__ import annotations

import doctest
import inspect

import pytest

import glradial

PUBLIC = sorted(name for name in glradial.__all__ if name != "__version__")


def _own_examples(obj: object, name: str) -> doctest.DocTest:
    """The doctest of ``obj``'s own docstring (not its methods')."""
    finder = doctest.DocTestFinder(recurse=False)
    tests = finder.find(obj, name=f"glradial.{name}", globs={})
    assert tests, f"glradial.{name} has no docstring"
    return tests[0]


@pytest.mark.parametrize("name", PUBLIC)
def test_a_public_name_documents_its_arguments_and_errors(name):
    obj = getattr(glradial, name)
    doc = inspect.getdoc(obj) or ""
    needed = ["Args:", "Raises:", "Example:"]
    if inspect.isfunction(obj):
        needed.append("Returns:")
    missing = [section for section in needed if section not in doc]
    assert not missing, f"glradial.{name}'s docstring lacks {missing}"


@pytest.mark.parametrize("name", PUBLIC)
def test_a_public_name_has_an_example_that_runs(name):
    test = _own_examples(getattr(glradial, name), name)
    assert test.examples, f"glradial.{name} has no >>> example"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    runner.run(test, out=lambda text: None)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"glradial.{name}'s example fails: run pytest --doctest-modules glradial"


def test_make_test_runs_the_doctests():
    from pathlib import Path

    makefile = (Path(__file__).resolve().parents[1] / "Makefile").read_text()
    test_target = makefile.split("\ntest:", 1)[1].split("\n\n", 1)[0]
    assert "--doctest-modules glradial" in test_target
