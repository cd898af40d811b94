"""Every Markdown table of the reports is built by one function, report.tables.grid: no other module
of the package writes a table's separator row, so no two tables can be built two ways."""

from __future__ import annotations

import ast
from pathlib import Path

from offroad_path.report.tables import grid, markdown_table
from offroad_path.statistics.scores import Record

PACKAGE = Path(__file__).resolve().parents[2] / "src" / "offroad_path"
BUILDER = PACKAGE / "report" / "tables.py"


def separators(path: Path) -> list[int]:
    """The lines of `path` whose string constants hold a Markdown separator cell ('--- |' or '| ---')."""
    return [
        node.lineno
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and ("--- |" in node.value or "| ---" in node.value)
    ]


def test_no_module_but_the_builder_writes_a_table():
    elsewhere = [
        f"{path.relative_to(PACKAGE)}:{line}" for path in sorted(PACKAGE.rglob("*.py")) if path != BUILDER for line in separators(path)
    ]
    assert elsewhere == []


def test_the_check_sees_a_table_built_by_hand(tmp_path):
    module = tmp_path / "table.py"
    module.write_text('rows = ["| a | b |", "|" + " --- |" * 2]\n')
    assert separators(module) == [1]


def test_the_builder_writes_header_separator_and_rows():
    assert grid(["a", "b"], [[1, "x"], [2.5, ""]]) == "| a | b |\n| --- | --- |\n| 1 | x |\n| 2.5 |  |"
    assert markdown_table([Record(network="unet", iou=0.5)]) == "| network | IoU |\n| --- | --- |\n| unet | 0.500 |\n"
