"""bench/figures.py: the record a bench writes under docs/figures/ (strict JSON, how it was measured)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from repo_scripts import load_script


def test_a_figure_is_strict_json_with_how_it_was_measured(tmp_path):
    figures = load_script("bench/figures.py")
    path = figures.write_figure("demo_bench", {"median_px": np.float64(2.5), "bad": float("nan"),
                                               "rows": [1, np.int64(2)]}, argv=["--x", "1"],
                                directory=tmp_path)
    record = json.loads(path.read_text())  # json.loads rejects nothing, so check the text too
    assert "NaN" not in path.read_text()
    assert record["results"] == {"median_px": 2.5, "bad": None, "rows": [1, 2]}
    assert record["command"].endswith("--x 1")
    assert record["machine"]["logical_cpus"] >= 1
    assert record["name"] == "demo_bench" and record["date"].endswith("Z")
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("name", ["", "a/b", "x y", "../up"])
def test_a_bad_name_is_refused(tmp_path, name):
    figures = load_script("bench/figures.py")
    with pytest.raises(ValueError, match="name"):
        figures.write_figure(name, {}, directory=tmp_path)


def test_a_printed_report_is_kept_and_still_printed(capsys):
    figures = load_script("bench/figures.py")
    with figures.printed_report() as lines:
        print("| a | b |")
        print("| 1 | 2 |")
    assert lines == ["| a | b |", "| 1 | 2 |"]
    assert capsys.readouterr().out == "| a | b |\n| 1 | 2 |\n"
