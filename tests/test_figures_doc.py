"""docs/FIGURES.md is what scripts/render_figures.py renders from docs/figures/*.json, every record
says how it was measured, and every bench writes its figures there (bench/figures.py)."""

from __future__ import annotations

import json
from pathlib import Path

from repo_scripts import load_script

ROOT = Path(__file__).resolve().parents[1]
#: bench/ files that measure nothing a document quotes: the figures module itself and a picture maker
NOT_FIGURES = {"figures.py", "lines_figure.py"}


def test_the_figures_document_is_up_to_date():
    render = load_script("scripts/render_figures.py")
    assert render.main(["--check"]) == 0, "run python scripts/render_figures.py"


def test_every_figure_says_how_it_was_measured():
    records = sorted((ROOT / "docs" / "figures").glob("*.json"))
    assert records
    for path in records:
        record = json.loads(path.read_text())
        assert record["name"] == path.stem
        assert record["date"][:4] == "2026" and record["command"].startswith(("python ", "bash scripts/", "glradial "))
        assert record["machine"] and "results" in record
        if "transcribed_from" in record:
            source = record["transcribed_from"].split(",")[0].split(" (")[0]
            assert source.endswith(".md"), source


def test_every_bench_writes_its_figures():
    silent = [p.name for p in sorted((ROOT / "bench").glob("*.py"))
              if p.name not in NOT_FIGURES and "write_figure(" not in p.read_text()]
    assert not silent, f"benches that write no figure (bench/figures.py write_figure): {silent}"


def test_a_figure_renders_as_rows_of_the_one_table(tmp_path):
    render = load_script("scripts/render_figures.py")
    (tmp_path / "x.json").write_text(json.dumps({
        "name": "x", "date": "2026-11-28T00:00:00Z", "commit": "abc", "dirty": False, "command": "python bench/x.py",
        "machine": {"cpu": "cpu", "logical_cpus": 2}, "results": {"fps": {"a": 1.23456}, "report": ["| t | u |", "| --- | --- |"]}}))
    text = render.render(tmp_path)
    assert ("| figure | how measured; results |\n| --- | --- |\n| **[x](figures/x.json)** | measured 2026-11-28T00:00Z "
            "on cpu (2 logical CPUs), commit abc: `python bench/x.py` |\n| fps | a **1.235** |\n| report | `\\| t \\| u \\|` |\n") in text
    assert "| --- | --- |" not in text.split("| fps |")[1]  # the report's separator is left out


def test_a_large_record_folds_into_few_rows_and_a_report_head(tmp_path):
    render = load_script("scripts/render_figures.py")
    results = {"m": {f"c{i}": {"auto": {"n": i, "median": 0.5}} for i in range(20)},
               "report": [f"line {i}" for i in range(10)]}
    lines = render.render_one({"name": "y", "date": "2026-11-28T00:00:00Z", "command": "python bench/y.py",
                               "machine": "here", "results": results})
    rows = [line for line in lines[1:] if not line.startswith("| report |") and not line.startswith("| | …")]
    assert len(rows) == 1 and rows[0].startswith("| m | c0 / auto: n **0**, median **0.5** · c1 / auto: n **1**")
    assert rows[0].endswith("c19 / auto: n **19**, median **0.5** |")
    assert sum(line.startswith("| report |") for line in lines) == render.REPORT_LINES
    assert lines[-1] == f"| | … {10 - render.REPORT_LINES} more lines in the JSON |"
