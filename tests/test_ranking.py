"""Score-and-rank (Zheng et al. Sec. 5.3.3) on toy tables with hand-computed scores."""

import pandas as pd
import pytest

from mcbench.ranking import case_scores, format_markdown, ranking_table


def _tidy(rows):
    return pd.DataFrame(rows, columns=["scene", "spp", "candidate", "metric", "value"])


def test_linear_scores_best_gets_number_of_entries_and_ties_share_the_mean():
    metrics = _tidy([
        ("s", 4, "noisy", "relmse", 9.0),
        ("s", 4, "a", "relmse", 1.0),
        ("s", 4, "b", "relmse", 2.0),
        ("s", 4, "c", "relmse", 2.0),
    ])
    scores = case_scores(metrics, "relmse").set_index("candidate")["score"]
    assert scores["a"] == 4.0          # best of 4 entries
    assert scores["noisy"] == 1.0      # worst
    assert scores["b"] == scores["c"] == 2.5  # tie on ranks 2 and 3 shares (3 + 2) / 2


def test_ranking_table_averages_over_scenes_then_spp():
    rows = []
    # spp 4: scene x: a < b < noisy ; scene y: b < a < noisy
    rows += [("x", 4, "a", "relmse", 1), ("x", 4, "b", "relmse", 2), ("x", 4, "noisy", "relmse", 3)]
    rows += [("y", 4, "a", "relmse", 2), ("y", 4, "b", "relmse", 1), ("y", 4, "noisy", "relmse", 3)]
    # spp 8: a best in both scenes
    rows += [("x", 8, "a", "relmse", 1), ("x", 8, "b", "relmse", 2), ("x", 8, "noisy", "relmse", 3)]
    rows += [("y", 8, "a", "relmse", 1), ("y", 8, "b", "relmse", 3), ("y", 8, "noisy", "relmse", 2)]
    # another metric must not leak in
    rows += [("x", 4, "a", "dssim", 100)]
    table = ranking_table(_tidy(rows), "relmse")
    assert list(table.columns) == ["4", "8", "Avg."]
    assert table.loc["a", "4"] == pytest.approx(2.5)   # (3 + 2) / 2
    assert table.loc["b", "4"] == pytest.approx(2.5)
    assert table.loc["a", "8"] == pytest.approx(3.0)
    assert table.loc["b", "8"] == pytest.approx(1.5)   # (2 + 1) / 2
    assert table.loc["noisy", "8"] == pytest.approx(1.5)
    assert table.loc["a", "Avg."] == pytest.approx(2.75)
    assert table.index[0] == "a"  # sorted best first


def test_markdown_uses_labels_and_marks_best():
    metrics = _tidy([("s", 4, "a", "relmse", 1.0), ("s", 4, "noisy", "relmse", 2.0)])
    text = format_markdown(ranking_table(metrics, "relmse"), {"a": "Method A"})
    assert "Method A" in text and "**2.0**" in text


def test_unknown_metric_raises():
    with pytest.raises(ValueError, match="dssim"):
        case_scores(_tidy([("s", 4, "a", "relmse", 1.0)]), "dssim")
