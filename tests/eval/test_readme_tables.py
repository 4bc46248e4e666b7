"""benchmarks/readme_tables.py: the README's tables are found, cut and rewritten between markers."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import benchmark_script

ROOT = Path(__file__).resolve().parents[2]

REPORT = """intro line

| check | observed objects | runs | top-1 | top-10 | localized | wrongly localized | median ms |
|---|---|---|---|---|---|---|---|
| ScanNet crops | 1-2 | 30 | 50% | 50% | 0% | 0% | 3 |
| ScanNet crops | all | 100 | 88% | 88% | 81% | 0% | 12 |
| 3RScan pair | 17 | 1 | 100% | 100% | 100% | 0% | 300 |

- details

| variant | objects | runs | top-1 | claims right | claims wrong | precision | coverage | top-10 | ms |
|---|---|---|---|---|---|---|---|---|---|
| clean | 3 | 60 | 90% | 20 | 0 | 100.0% | 33% | 95% | 9 |
| clean | all | 180 | 95% | 80 | 1 | 98.8% | 44% | 97% | 9 |
"""


def test_tables_are_parsed_with_their_headers():
    tables = benchmark_script("readme_tables").markdown_tables(REPORT)
    assert [len(t) for t in tables] == [4, 3]
    assert tables[0][0][:4] == ["check", "observed objects", "runs", "top-1"]
    assert tables[1][2][:3] == ["clean", "all", "180"]


def test_rows_and_columns_are_selected_in_the_specs_order():
    script = benchmark_script("readme_tables")
    tables = script.markdown_tables(REPORT)
    crops = script.select(tables[0], script.TABLES["real-layouts"])
    assert [row[1] for row in crops] == ["observed objects", "all", "17"]
    assert crops[1] == ["ScanNet crops", "all", "100", "88%", "88%", "81%", "0%"]  # no ms
    trust = script.select(tables[1], script.TABLES["trust"])
    assert trust == [
        ["variant", "objects", "runs", "top-1", "top-10", "claims right", "claims wrong",
         "precision", "coverage"],
        ["clean", "all", "180", "95%", "97%", "80", "1", "98.8%", "44%"],
    ]  # fmt: skip


def test_a_missing_column_is_a_clear_error():
    script = benchmark_script("readme_tables")
    with pytest.raises(SystemExit, match="no column"):
        script.select([["a", "b"], ["1", "2"]], script.TableSpec("x", 0, columns=("c",)))


def test_only_the_text_between_the_markers_is_rewritten():
    script = benchmark_script("readme_tables")
    readme = "top\n<!-- table: trust -->\nold\ntable\n<!-- /table -->\nbottom\n"
    text = script.rewritten(readme, ["trust"], {"real": REPORT})
    assert text.startswith("top\n<!-- table: trust -->\n`python benchmarks/real_layouts.py")
    assert (
        "| clean | all | 180 | 95% | 97% | 80 | 1 | 98.8% | 44% |\n<!-- /table -->\nbottom\n"
        in text
    )
    assert "old" not in text
    unchanged = script.rewritten(readme, ["trust"], {"real": None})  # the benchmark did not run
    assert unchanged == readme
    with pytest.raises(SystemExit, match="no markers"):
        script.rewritten("no markers here", ["trust"], {"real": REPORT})


def test_every_page_has_the_markers_of_its_tables():
    script = benchmark_script("readme_tables")
    for page in {spec.file for spec in script.TABLES.values()}:
        text = (ROOT / page).read_text(encoding="utf-8")
        mine = [name for name, spec in script.TABLES.items() if spec.file == page]
        for name in mine:
            assert f"<!-- table: {name} -->" in text, (page, name)
        assert text.count("<!-- /table -->") == len(mine), page
