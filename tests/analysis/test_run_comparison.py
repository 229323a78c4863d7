"""Two runs' tables compared (mcbench.analysis.run_comparison) on constructed results folders whose
differences are known: a timing column is ignored, any other change is found and measured."""

import numpy as np
import pandas as pd
import pytest

from mcbench.analysis import run_comparison
from mcbench.analysis.run_comparison import compare_images, compare_runs, table_contents, table_without_timing
from mcbench.io.exr import write_layers

MARKDOWN = """# Ranking

| candidate | relMSE | seconds |
| --- | ---: | ---: |
| oidn | 0.0123 | {seconds} |
| nfor | {nfor} | 3.5 |

Measured on {machine}: wall time {seconds} s.
"""


def _results(root, *, nfor=0.0456, seconds=1.25, machine="host-a", metric_value=0.5, cpu=10.0, extra=False):
    """A results folder with metrics.csv, a CSV with a timing column, a Markdown table and a
    progressive table, each value settable."""
    (root / "tables" / "study").mkdir(parents=True)
    (root / "progressive" / "cornell_box").mkdir(parents=True)
    pd.DataFrame({"scene": ["a", "a"], "spp": [4, 16], "entry": ["oidn", "nfor"],
                  "metric": ["relmse"] * 2, "value": [metric_value, 0.25]}).to_csv(root / "metrics.csv", index=False)
    pd.DataFrame({"candidate": ["oidn", "nfor"], "score": [12.5, 7.0], "cpu_seconds": [cpu, 2 * cpu]}).to_csv(
        root / "tables" / "ranking.csv", index=False)
    (root / "tables" / "study" / "summary.md").write_text(MARKDOWN.format(nfor=nfor, seconds=seconds, machine=machine))
    (root / "tables" / ".summary.md.crc32").write_text(f"{seconds}\n")          # a checksum: not a table
    (root / "progressive" / "cornell_box" / "curve.csv").write_text("spp,relmse,wall_seconds\n4,0.5,1.0\n")
    if extra:
        (root / "tables" / "new.tex").write_text("\\begin{tabular}\\end{tabular}\n")
    return root


def test_runs_that_differ_only_in_time_are_the_same_study(tmp_path):
    a = _results(tmp_path / "a")
    b = _results(tmp_path / "b", seconds=99.0, machine="host-b", cpu=30.0)
    assert compare_runs(a, b) == []
    assert set(table_contents(a)) == {"metrics.csv", "tables/ranking.csv", "tables/study/summary.md",
                                      "progressive/cornell_box/curve.csv"}


def test_a_changed_value_is_found_and_measured(tmp_path):
    a = _results(tmp_path / "a")
    b = _results(tmp_path / "b", metric_value=0.5005, nfor=0.0457, extra=True)
    found = {d.table: d for d in compare_runs(a, b)}
    assert set(found) == {"metrics.csv", "tables/study/summary.md", "tables/new.tex"}
    assert found["tables/new.tex"].status == "only in b"
    metrics = found["metrics.csv"]
    assert metrics.status == "differs" and metrics.cells == 1
    assert metrics.max_abs == pytest.approx(0.0005) and metrics.max_rel == pytest.approx(0.0005 / 0.5005)
    assert found["tables/study/summary.md"].cells is None          # Markdown: found, not measured


def test_markdown_drops_the_timing_column_and_timed_lines_only(tmp_path):
    path = tmp_path / "t.md"
    path.write_text(MARKDOWN.format(nfor=0.0456, seconds=1.25, machine="m"))
    kept = table_without_timing(path).split("\n")
    assert kept[0] == "# Ranking" and kept[7] == ""
    assert kept[2] == " candidate | relMSE " and kept[4] == " oidn | 0.0123 " and kept[5] == " nfor | 0.0456 "


def test_a_pattern_that_matched_every_column_would_hide_a_change(tmp_path, monkeypatch):
    """The check can fail: were every column taken for a timing column, a changed score would go
    unseen, and this test shows the comparison depends on the pattern."""
    a = _results(tmp_path / "a")
    b = _results(tmp_path / "b", nfor=0.9)
    assert compare_runs(a, b)
    monkeypatch.setattr(run_comparison, "TIMING_COLUMN", run_comparison.re.compile(r".*"))
    assert not [d for d in compare_runs(a, b) if d.table.endswith(".md")]


def test_images_are_compared_value_by_value(tmp_path):
    rng = np.random.default_rng(3)
    color = rng.random((4, 5, 3), dtype=np.float32)
    for run in "ab":
        (tmp_path / run / "renders" / "s").mkdir(parents=True)
        write_layers(tmp_path / run / "renders" / "s" / "spp4.exr", {"color": color})
    changed = color.copy()
    changed[1, 2, 0] += 0.25
    write_layers(tmp_path / "a" / "renders" / "s" / "spp8.exr", {"color": color})
    write_layers(tmp_path / "b" / "renders" / "s" / "spp8.exr", {"color": changed})
    found = compare_images(tmp_path / "a", tmp_path / "b", "renders")
    assert [d.table for d in found] == ["renders/s/spp8.exr"]
    assert found[0].cells == 1 and found[0].max_abs == pytest.approx(0.25, abs=1e-6)
    assert found[0].max_rel == pytest.approx(0.25 / changed[1, 2, 0], rel=1e-6)


def test_a_folder_without_metrics_is_refused(tmp_path):
    with pytest.raises(ValueError, match="metrics.csv"):
        table_contents(tmp_path)


LONG_CSV = "entry,4,16,quantity\noidn,{relmse},0.02,relmse\noidn,{seconds},0.17,seconds\n"
SECTIONED = """**Consistency curve: cornell_box at 64x64, seed 0; {seconds} s**

## relMSE

| entry | 4 |
| --- | --- |
| oidn | {relmse} |

## seconds per case (own compute)

| entry | 4 |
| --- | --- |
| oidn | {seconds} |
"""


@pytest.mark.parametrize("template, suffix", [(LONG_CSV, ".csv"), (SECTIONED, ".md")])
def test_timing_rows_sections_and_durations_are_left_out_and_nothing_else(tmp_path, template, suffix):
    """A long table's ``seconds`` rows, a Markdown section headed by a timing word and a caption's
    duration ("63 s") are timing; the relMSE beside them is not."""
    texts = {}
    for name, relmse, seconds in [("a", 0.0305, 0.177), ("b", 0.0305, 0.69), ("c", 0.0306, 0.177)]:
        path = tmp_path / f"{name}{suffix}"
        path.write_text(template.format(relmse=relmse, seconds=seconds))
        texts[name] = table_without_timing(path)
    assert texts["a"] == texts["b"]
    assert texts["a"] != texts["c"]
    assert "0.0305" in texts["a"] and "0.177" not in texts["a"]


def test_an_ignore_pattern_leaves_out_renamed_module_paths_only(tmp_path):
    """Comparing across a refactoring: the captions' module paths changed, a value did not; with
    the pattern the runs agree, and a changed value is still found."""
    a = _results(tmp_path / "a")
    b = _results(tmp_path / "b")
    c = _results(tmp_path / "c", nfor=0.0457)
    for root, module in [(a, "mcbench.ranking"), (b, "mcbench.analysis.ranking"), (c, "mcbench.analysis.ranking")]:
        (root / "tables" / "ranking.tex").write_text(f"% Written by mcbench ({module}.format_latex).\n\\toprule\n")
    pattern = run_comparison.re.compile(r"mcbench[./][A-Za-z_./]*")
    assert [d.table for d in compare_runs(a, b)] == ["tables/ranking.tex"]
    assert compare_runs(a, b, ignore=pattern) == []
    assert [d.table for d in compare_runs(a, c, ignore=pattern)] == ["tables/study/summary.md"]
