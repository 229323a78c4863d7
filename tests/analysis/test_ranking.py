"""Score-and-rank (Zheng et al. Sec. 5.3.3) on toy tables with hand-computed scores."""

import pandas as pd
import pytest

from mcbench.analysis.ranking import case_scores, format_markdown, ranking_table


def _tidy(rows):
    return pd.DataFrame(rows, columns=["scene", "spp", "entry", "metric", "value"])


def test_linear_scores_best_gets_number_of_entries_and_ties_share_the_mean():
    metrics = _tidy([
        ("s", 4, "noisy", "relmse", 9.0),
        ("s", 4, "a", "relmse", 1.0),
        ("s", 4, "b", "relmse", 2.0),
        ("s", 4, "c", "relmse", 2.0),
    ])
    scores = case_scores(metrics, "relmse").set_index("entry")["score"]
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


# --- incomplete tables stop instead of being ranked -----------------------------------------

def _full_case(scene="s", spp=4, entries=("noisy", "a", "b"), metrics=("relmse", "dssim")):
    return [(scene, spp, e, m, float(i + 1)) for i, e in enumerate(entries) for m in metrics]


def test_a_case_missing_a_candidate_is_not_ranked_on_another_scale():
    from mcbench.analysis.ranking import IncompleteMetricsError

    rows = _full_case("x") + [r for r in _full_case("y") if r[2] != "b"]
    with pytest.raises(IncompleteMetricsError, match=r"scene y, spp 4 is incomplete: missing \[\('b', 'dssim'\)"):
        ranking_table(_tidy(rows), "dssim")


def test_non_finite_or_empty_values_stop_naming_the_case():
    from mcbench.analysis.ranking import IncompleteMetricsError, check_complete

    rows = _full_case()
    rows[3] = rows[3][:4] + (float("nan"),)
    with pytest.raises(IncompleteMetricsError, match=r"1 value\(s\) missing or not finite, first at scene s, spp 4, a, dssim"):
        check_complete(_tidy(rows), entries=["noisy", "a", "b"], metric_names=["relmse", "dssim"])


def test_check_complete_refuses_duplicates_extras_and_lost_cases():
    from mcbench.analysis.ranking import IncompleteMetricsError, check_complete

    kwargs = dict(entries=["noisy", "a", "b"], metric_names=["relmse", "dssim"])
    check_complete(_tidy(_full_case()), **kwargs, cases=[("s", 4)])
    with pytest.raises(IncompleteMetricsError, match="duplicated"):
        check_complete(_tidy(_full_case() + _full_case()[:1]), **kwargs)
    with pytest.raises(IncompleteMetricsError, match="unexpected"):
        check_complete(_tidy(_full_case(entries=("noisy", "a", "b", "c"))), **kwargs)
    with pytest.raises(IncompleteMetricsError, match=r"no rows for case\(s\) \[\('s', 8\)\]"):
        check_complete(_tidy(_full_case()), **kwargs, cases=[("s", 4), ("s", 8)])


def _write_case(path, rows):
    _tidy(rows).to_csv(path, index=False)
    return str(path)


def test_gather_refuses_a_case_csv_cut_mid_row(tmp_path):
    """A per-case CSV cut in the middle of a row (an empty value, rows dropped) stops the gather
    with the file named, instead of moving scores."""
    from mcbench import BenchError
    from mcbench.pipeline.evaluation import gather_tables

    kwargs = dict(entries=["noisy", "a", "b"], metric_names=["relmse", "dssim"])
    good = _write_case(tmp_path / "x.csv", _full_case("x"))
    cut = tmp_path / "y.csv"
    text = _tidy(_full_case("y")).to_csv(index=False)
    cut.write_text(text[: text.index("a,dssim") + len("a,dssim,")])   # last row without its value
    with pytest.raises(BenchError, match="y.csv"):
        gather_tables([good, str(cut)], str(tmp_path / "all.csv"), cases=[("x", 4), ("y", 4)], **kwargs)
    assert not (tmp_path / "all.csv").exists()
    wrong_case = _write_case(tmp_path / "z.csv", _full_case("z"))
    with pytest.raises(BenchError, match=r"z.csv: no rows for case\(s\) \[\('w', 4\)\]"):
        gather_tables([wrong_case], str(tmp_path / "all.csv"), cases=[("w", 4)], **kwargs)
    frame = gather_tables([good], str(tmp_path / "all.csv"), cases=[("x", 4)], **kwargs)
    assert len(frame) == 6 and pd.read_csv(tmp_path / "all.csv").equals(frame)


def test_write_rankings_refuses_a_table_with_other_candidates(tmp_path):
    from mcbench import BenchError
    from mcbench.pipeline.rankings import write_rankings

    path = _write_case(tmp_path / "metrics.csv", _full_case())
    write_rankings(path, "relmse", str(tmp_path / "r.csv"), str(tmp_path / "r.md"),
                   entries=["noisy", "a", "b"], labels={})
    table = pd.read_csv(tmp_path / "r.csv")
    assert list(table["candidate"]) == ["noisy", "a", "b"]      # lowest error first: noisy = 1.0
    with pytest.raises(BenchError, match=r"missing \[\('c', 'relmse'\)\]"):
        write_rankings(path, "relmse", str(tmp_path / "r2.csv"), str(tmp_path / "r2.md"),
                       entries=["noisy", "a", "b", "c"], labels={})


# --- LaTeX tables ------------------------------------------------------------------------------

def _latex_toy_table():
    """Three candidates, two scenes, two spp, scores by hand: spp 4: a 3, noisy 1.5, b_x 1.5;
    spp 64: b_x 3, a 1.5, noisy 1.5; Avg.: a and b_x tie at 2.25 (both bold), noisy 1.5."""
    rows = [("s", 4, "a", "relmse", 1.0), ("s", 4, "noisy", "relmse", 2.0), ("s", 4, "b_x", "relmse", 3.0),
            ("s", 64, "a", "relmse", 3.0), ("s", 64, "noisy", "relmse", 2.5), ("s", 64, "b_x", "relmse", 1.0),
            ("t", 4, "a", "relmse", 1.0), ("t", 4, "noisy", "relmse", 3.0), ("t", 4, "b_x", "relmse", 2.0),
            ("t", 64, "a", "relmse", 2.0), ("t", 64, "noisy", "relmse", 3.0), ("t", 64, "b_x", "relmse", 1.0)]
    return ranking_table(_tidy(rows), "relmse")


def _body_rows(text):
    body = text.split("\\midrule\n")[1].split("\\bottomrule")[0]
    return [line.strip() for line in body.strip().splitlines()]


def _cells(row):
    assert row.endswith(r"\\")
    return [cell.strip() for cell in row[:-2].split(" & ")]


def test_latex_table_is_booktabs_with_one_row_per_candidate_and_bold_at_each_column_max():
    from mcbench.analysis.ranking import format_latex

    table = _latex_toy_table()
    labels = {"a": "#1 KPCN† (ours; 50% & more)", "b_x": "Ensemble (oidn+jbf)"}
    text = format_latex(table, labels, caption="Ranking by relMSE_x.", label="tab:ranking-relmse")
    # structure: balanced braces, environments opened and closed, rules in booktabs order
    assert text.count("{") == text.count("}")
    depth = 0
    for char in text.replace(r"\{", "").replace(r"\}", ""):
        depth += {"{": 1, "}": -1}.get(char, 0)
        assert depth >= 0
    for env in ("table", "tabular"):
        assert text.count(rf"\begin{{{env}}}") == text.count(rf"\end{{{env}}}") == 1
    assert text.index(r"\toprule") < text.index(r"\midrule") < text.index(r"\bottomrule")
    assert r"\begin{tabular}{lrrr}" in text
    assert r"\caption{Ranking by relMSE\_x.}" in text and r"\label{tab:ranking-relmse}" in text
    header = text.split("\\toprule\n")[1].split("\\midrule")[0].strip()
    assert _cells(header) == ["Candidate", "4 spp", "64 spp", "Avg."]
    rows = _body_rows(text)
    assert len(rows) == len(table) == 3
    assert table.loc["a", "4"] == 3.0 and table.loc["b_x", "64"] == 3.0
    assert table.loc["a", "Avg."] == table.loc["b_x", "Avg."] == 2.25 and table.loc["noisy", "Avg."] == 1.5
    shown = {"a": r"\#1 KPCN\dag{} (ours; 50\% \& more)", "b_x": "Ensemble (oidn+jbf)", "noisy": "noisy"}
    for row, candidate in zip(rows, table.index):
        cells = _cells(row)
        assert cells[0] == shown[candidate]
        for cell, column in zip(cells[1:], table.columns):
            value = table.loc[candidate, column]
            is_max = value == table[column].max()
            assert cell == (rf"\textbf{{{value:.1f}}}" if is_max else f"{value:.1f}"), (candidate, column)
    # the toy table has a strict best in the spp columns (so bold is not everywhere)
    assert table["4"].tolist().count(table["4"].max()) == 1
    assert sum(r"\textbf" in _cells(r)[1] for r in rows) == 1


def test_latex_escapes_and_refuses_a_bad_label():
    from mcbench.analysis.ranking import format_latex, latex_escape

    assert latex_escape("a_b & c% #1 $x$ {y} ~^\\ †+") == (r"a\_b \& c\% \#1 \$x\$ \{y\} \textasciitilde{}"
                                                          r"\textasciicircum{}\textbackslash{} \dag{}+")
    with pytest.raises(ValueError, match="label"):
        format_latex(_latex_toy_table(), caption="x", label="tab:bad label}")
    assert r"\textbf{3.000}" in format_latex(_latex_toy_table(), caption="x", label="t", digits=3)


def test_write_rankings_writes_the_latex_table(tmp_path):
    from mcbench.pipeline.rankings import write_rankings

    path = _write_case(tmp_path / "metrics.csv", _full_case())
    table = write_rankings(path, "dssim", str(tmp_path / "r.csv"), str(tmp_path / "r.md"),
                           entries=["noisy", "a", "b"], labels={"a": "Method_A"},
                           tex_path=str(tmp_path / "r.tex"))
    text = (tmp_path / "r.tex").read_text()
    assert r"\label{tab:ranking-dssim}" in text and r"\caption{Ranking by DSSIM." in text
    assert "Higher is better" in text and "Best per column in bold" in text
    assert len(_body_rows(text)) == len(table) == 3 and r"Method\_A" in text
    # without tex_path, no LaTeX file
    write_rankings(path, "dssim", str(tmp_path / "q.csv"), str(tmp_path / "q.md"),
                   entries=["noisy", "a", "b"], labels={})
    assert not (tmp_path / "q.tex").exists()


def test_extras_are_scored_each_alone_in_the_pool_by_hand():
    # pool: a, b, noisy; extras x (best in the case), y (between a and b)
    metrics = _tidy([
        ("s", 4, "a", "relmse", 1.0), ("s", 4, "b", "relmse", 3.0), ("s", 4, "noisy", "relmse", 9.0),
        ("s", 4, "x", "relmse", 0.5), ("s", 4, "y", "relmse", 2.0),
        ("t", 4, "a", "relmse", 2.0), ("t", 4, "b", "relmse", 1.0), ("t", 4, "noisy", "relmse", 9.0),
        ("t", 4, "x", "relmse", 9.0), ("t", 4, "y", "relmse", 1.0),
    ])
    from mcbench.analysis.ranking import extras_table

    table = extras_table(metrics, "relmse", pool=["a", "b", "noisy"], extras=["y", "x"])
    assert list(table.index) == ["y", "x"]
    # scene s: x beats all 3 -> 4; y beats b and noisy -> 3. scene t: x ties noisy at the bottom
    # -> (1 + 2) / 2 = 1.5; y ties b at the top -> (4 + 3) / 2 = 3.5
    assert table.loc["x", "4"] == pytest.approx((4 + 1.5) / 2)
    assert table.loc["y", "4"] == pytest.approx((3 + 3.5) / 2)
    # the pool's own scores do not move whatever the extras are
    pool_only = ranking_table(metrics[metrics["entry"].isin(["a", "b", "noisy"])], "relmse")
    assert pool_only.loc["a", "Avg."] == pytest.approx((3 + 2) / 2)
    with pytest.raises(Exception, match="incomplete|missing"):
        extras_table(metrics[metrics["entry"] != "x"], "relmse", pool=["a", "b", "noisy"], extras=["x"])


def test_ranking_rows_follow_a_given_order_and_refuse_a_wrong_one():
    metrics = _tidy([("s", 4, "a", "relmse", 2.0), ("s", 4, "b", "relmse", 1.0), ("s", 4, "noisy", "relmse", 3.0)])
    assert list(ranking_table(metrics, "relmse").index) == ["b", "a", "noisy"]
    assert list(ranking_table(metrics, "relmse", order=["a", "b", "noisy"]).index) == ["a", "b", "noisy"]
    with pytest.raises(ValueError, match="order"):
        ranking_table(metrics, "relmse", order=["a", "noisy"])
