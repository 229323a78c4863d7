"""End-to-end runs of the Snakemake DAG on the tiny smoke config (a few 32×32 scenes, two
spp levels). One shared run (the session's ``smoke_results``) is checked a family of outputs a
test: metrics.csv, the ranking and extras tables, the study's tables and figures, the
comparisons, progressive denoising, the oracle study, the timings and the report's figures, each
recomputed from metrics.csv or held to the ranges of its definitions, figures decoded and sized
in pixels. Then: the ensemble beats the noisy input, a killed run resumes, and bad inputs stop
the run with an error naming the file or config key while keeping finished outputs."""

from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from tests.conftest import REPO, SMOKE_CONFIG as SMOKE, run_snakemake as snakemake

pytestmark = pytest.mark.slow


def write_config(workdir: Path, **changes) -> dict:
    config = yaml.safe_load(SMOKE.read_text())
    config.update(changes)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "config.yaml").write_text(yaml.safe_dump(config))
    return config


@pytest.fixture(scope="module")
def smoke_run(smoke_results):
    """The session's smoke run (tests/conftest.py), shared with the report tests."""
    return smoke_results


@pytest.fixture(scope="module")
def results(smoke_run) -> Path:
    return smoke_run[0] / "results"


@pytest.fixture(scope="module")
def metrics(results) -> pd.DataFrame:
    return pd.read_csv(results / "metrics.csv")


@pytest.fixture(scope="module")
def timings(results) -> pd.DataFrame:
    return pd.read_csv(results / "timings.csv")


SPPS = [4, 64]                                                     # the smoke config's spp
POOL_SLICE = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "ens15"]   # study.ensembles [10, 15], in ID order
POOL_IDS = [1, 4, 6, 8, 10, 15]
PAIRS = {"ens10": ["kpcn", "nfor"], "ens15": ["oidn", "rdfc"]}     # the size-2 ensembles and their members
RANKED = POOL_SLICE + ["noisy"]                                    # the ranking pool, in its tables' order
EXTRAS = ["jbf", "ensemble", "ensemble_exact", "onehot_sbf", "onehot_nfor", "onehot_post", "naive",
          "ensemble_unconstrained", "pd_oidn"]
METRICS = ("relmse", "relmse_corrected", "smape", "dssim", "flip")
SCORE_TOL = 5e-5              # scores and score means are written with 4 decimals
DPI = 110                     # mcbench.analysis.error_speed_figures.save_figure: PNGs of figsize x 110 pixels, no cropping


def _wide(metrics: pd.DataFrame, metric: str) -> pd.DataFrame:
    """metrics.csv's values of one metric: index (scene, spp), one column per entry."""
    return metrics[metrics.metric == metric].pivot_table(index=["scene", "spp"], columns="entry", values="value")


def _scores_by_counting(values: pd.DataFrame) -> pd.DataFrame:
    """Sec. 5.3.3 by counting: score = 1 + (entries with a larger error) + (ties) / 2."""
    return values.apply(lambda row: row.map(lambda v: 1 + (row > v).sum() + ((row == v).sum() - 1) / 2), axis=1)


def _mean_scores(values: pd.DataFrame, entries: list[str]) -> pd.DataFrame:
    """The entries scored among themselves case by case, averaged over scenes: rows entries,
    columns spp (ints) and ``Avg.`` (the mean over spp)."""
    table = _scores_by_counting(values[entries]).groupby(level="spp").mean().T
    table["Avg."] = table.mean(axis=1)
    return table


def _score_table(path: Path, candidates: list[str]) -> pd.DataFrame:
    """A table of scores (ranking, extras) read from ``path``: columns candidate, the spp and
    ``Avg.``, rows ``candidates`` in that order, every score finite; indexed by candidate."""
    table = pd.read_csv(path)
    assert list(table.columns) == ["candidate", "4", "64", "Avg."], path
    assert list(table["candidate"]) == candidates, path
    table = table.set_index("candidate")
    assert np.isfinite(table.to_numpy()).all(), path
    return table


def _markdown_rows(text: str) -> list[list[str]]:
    """The cells of a Markdown pipe table's body rows (header and rule left out)."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    return [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[2:]]


def _assert_within(low, estimate, high, *, tol: float, what: str) -> None:
    """low <= estimate <= high (to ``tol``) wherever an interval is written (both bounds present)."""
    low, estimate, high = (np.asarray(v, np.float64) for v in (low, estimate, high))
    present = np.isfinite(low) & np.isfinite(high)
    assert present.any(), f"{what}: no interval at all"
    bad = present & ~((low <= estimate + tol) & (estimate <= high + tol))
    assert not bad.any(), f"{what}: estimate outside its interval at rows {np.flatnonzero(bad)}"


def _assert_png(path, *, inches: tuple[float, float] | None = None, width_inches: float | None = None) -> None:
    """``path`` (a file's path, or a binary file object) decodes as a PNG of figsize ``inches`` (or
    only the width) at :data:`DPI`, with a drawing on it (many colours: lines, text, antialiasing;
    a blank or single-colour image fails)."""
    from PIL import Image

    with Image.open(path) as image:
        assert image.format == "PNG", path
        rgb = image.convert("RGB")                    # decodes every pixel
    width, height = rgb.size
    if inches is not None:
        assert (width, height) == (round(inches[0] * DPI), round(inches[1] * DPI)), (path, width, height)
    if width_inches is not None:
        assert width == round(width_inches * DPI), (path, width)
    assert rgb.getcolors(maxcolors=16) is None, f"{path}: blank figure (16 colours or fewer)"


# --- metrics.csv and the claims checked on it -------------------------------------------------

def test_metrics_table_holds_every_case_entry_and_metric_once(smoke_run, metrics):
    _, config = smoke_run
    assert list(metrics.columns) == ["scene", "spp", "entry", "metric", "value"]
    twice = metrics[metrics.duplicated(["scene", "spp", "entry", "metric"], keep=False)]
    assert twice.empty, f"rows written twice:\n{twice}"
    assert sorted(set(metrics.scene)) == sorted(config["scenes"]) and sorted(set(metrics.spp)) == SPPS
    assert set(metrics.entry) == set(RANKED + EXTRAS) and set(metrics.metric) == set(METRICS)
    assert len(metrics) == 3 * 2 * 16 * 5  # scenes × spp × (candidates + noisy) × metrics
    assert np.isfinite(metrics["value"]).all()
    # the ranges of the definitions (mcbench.analysis.metrics): relMSE >= 0, SMAPE and FLIP in [0, 1],
    # DSSIM = 1 - SSIM in [0, 2]
    for metric, (low, high) in {"relmse": (0, np.inf), "smape": (0, 1), "flip": (0, 1), "dssim": (0, 2)}.items():
        values = metrics.loc[metrics.metric == metric, "value"]
        assert values.between(low, high).all(), (metric, values.min(), values.max())


def test_the_ensembles_beat_the_noisy_input_and_their_worst_member(results, metrics):
    relmse = _wide(metrics, "relmse")
    # At 32x32 the denoisers' blur of the Cornell box's light edge can cost more relMSE than
    # the noise they remove in a single case, so the claim is checked over all cases: the
    # ensemble's mean relMSE and its relMSE ranking score beat the noisy input's.
    assert relmse["ensemble"].mean() < relmse["noisy"].mean(), relmse
    ranking = pd.read_csv(results / "tables/ranking_relmse.csv").set_index("candidate")
    assert ranking.loc["ens15", "Avg."] > ranking.loc["noisy", "Avg."]
    # the ensembles are never worse than their worst base denoiser, case by case
    assert (relmse["ensemble"] <= relmse[["oidn", "jbf"]].max(axis=1)).all(), relmse
    assert (relmse["ens15"] <= relmse[["oidn", "rdfc"]].max(axis=1)).all(), relmse


# --- ranking and extras tables ------------------------------------------------------------------

@pytest.mark.parametrize("metric", METRICS)
def test_ranking_table_is_the_pool_scored_case_by_case(results, metrics, metric):
    # the ranking pool: the pool's slice in ID order, then the noisy input; nothing else
    table = _score_table(results / f"tables/ranking_{metric}.csv", RANKED)
    k = len(RANKED)
    assert ((table >= 1 - SCORE_TOL) & (table <= k + SCORE_TOL)).all().all(), table
    # every case's scores are a permutation of 1..K (ties averaged), so every spp column, a mean
    # over scenes, sums to K (K + 1) / 2
    np.testing.assert_allclose(table[["4", "64"]].sum(), k * (k + 1) / 2, atol=k * SCORE_TOL)
    # every value recomputed independently from metrics.csv
    expected = _mean_scores(_wide(metrics, metric), RANKED)
    for spp in SPPS:
        np.testing.assert_allclose(table[str(spp)], expected.loc[RANKED, spp], atol=SCORE_TOL)
    np.testing.assert_allclose(table["Avg."], expected.loc[RANKED, "Avg."], atol=SCORE_TOL)
    # the Markdown: the pool note, one row per candidate with the CSV's scores to one decimal, the
    # best of each column in bold
    text = (results / f"tables/ranking_{metric}.md").read_text()
    assert text.startswith(f"# Ranking by {metric}") and "Partial pool: 6 of the 39 candidates" in text
    rows = _markdown_rows(text)
    assert len(rows) == k and all(len(row) == 4 for row in rows), rows
    for j, column in enumerate(["4", "64", "Avg."], start=1):
        shown = [float(row[j].strip("*")) for row in rows]
        np.testing.assert_allclose(shown, table[column].round(1), atol=0.051)
        bold = [row[j].startswith("**") for row in rows]
        assert bold == list(np.isclose(table[column], table[column].max())), (column, rows)
    tex = (results / f"tables/ranking_{metric}.tex").read_text()
    assert r"\begin{tabular}{lrrr}" in tex and tex.count(r" \\" + "\n") == k + 1   # header and a row each


@pytest.mark.parametrize("metric", METRICS)
def test_extras_table_scores_each_extra_added_alone_to_the_pool(results, metrics, metric):
    extras = _score_table(results / f"tables/extras_{metric}.csv", EXTRAS)
    values = _wide(metrics, metric)
    for name in EXTRAS:
        alone = _mean_scores(values, RANKED + [name]).loc[name]
        np.testing.assert_allclose(extras.loc[name, ["4", "64", "Avg."]].to_numpy(float),
                                   alone[[4, 64, "Avg."]].to_numpy(float), atol=SCORE_TOL, err_msg=name)
    assert ((extras >= 1 - SCORE_TOL) & (extras <= len(RANKED) + 1 + SCORE_TOL)).all().all(), extras
    text = (results / f"tables/extras_{metric}.md").read_text()
    assert len(_markdown_rows(text)) == len(EXTRAS)


# --- the study's tables (results/tables/study) ------------------------------------------------

def test_study_writes_every_table_with_its_columns(results):
    from mcbench.analysis.study.findings import FINDING_COLUMNS
    from mcbench.analysis.study.pair_members import PAIR_COLUMNS
    from mcbench.analysis.study.recommendations import BOTH_COLUMNS, REC_COLUMNS
    from mcbench.analysis.study.reference_noise import REFERENCE_NOISE_COLUMNS
    from mcbench.analysis.study.statistics import SCORE_CI_COLUMNS
    from mcbench.analysis.study.writers import STUDY_FILES

    from mcbench.io.checksums import check_bytes

    study = results / "tables/study"
    files = sorted(p for p in study.iterdir() if not p.name.startswith("."))     # hidden: checksum side files
    assert [p.name for p in files] == sorted([*STUDY_FILES, *(f"scores_ci_{m}.csv" for m in METRICS)])
    for path in files:
        check_bytes(path, path.read_bytes())          # each matches the checksum written with it
    columns = {"recommendations": REC_COLUMNS, "recommendations_metrics": BOTH_COLUMNS, "findings": FINDING_COLUMNS,
               "pair_members": PAIR_COLUMNS, "reference_noise": REFERENCE_NOISE_COLUMNS,
               "paper_table3": ["id", "candidate", "spp", "ours", "paper", "difference", "note"],
               **{f"scores_ci_{m}": SCORE_CI_COLUMNS for m in METRICS}}
    for stem, expected in columns.items():
        table = pd.read_csv(study / f"{stem}.csv")
        assert list(table.columns) == list(expected), stem
        assert len(table), f"{stem}.csv has no rows"
    for path in study.glob("*.md"):
        assert path.read_text().startswith("# "), path.name
    summary = (study / "summary.md").read_text()
    for label in ("relMSE", "SMAPE", "DSSIM"):
        assert f"- {label}: 3 scene(s), spp 4, 64, 7 entries (the paper: 40)" in summary, label
    for heading in ("## Recommendations", "## Beside the paper's Table 3", "## References", "## Findings"):
        assert heading in summary


@pytest.mark.parametrize("metric", METRICS)
def test_study_score_intervals_hold_the_ranking_scores(results, metric):
    ci = pd.read_csv(results / f"tables/study/scores_ci_{metric}.csv")
    ranking = pd.read_csv(results / f"tables/ranking_{metric}.csv").set_index("candidate")
    assert list(ci["candidate"]) == RANKED
    assert list(ci["id"].iloc[:-1].astype(int)) == POOL_IDS and pd.isna(ci["id"].iloc[-1])
    # Avg. and the spp bands (low: 4-32 spp, medium: 32-256 spp; none of our spp is high)
    for column, source in (("avg", "Avg."), ("low", "4"), ("medium", "64")):
        np.testing.assert_allclose(ci[column], ranking.loc[RANKED, source], atol=2 * SCORE_TOL, err_msg=column)
        _assert_within(ci[f"{column}_ci_low"], ci[column], ci[f"{column}_ci_high"], tol=2e-4, what=column)
    assert ci[["high", "high_ci_low", "high_ci_high"]].isna().all().all()
    assert set(ci["ci_method"]) <= {"BCa", "percentile (BCa degenerate)"}


def test_study_recommendations_pick_the_best_scored_ensemble(results):
    rec = pd.read_csv(results / "tables/study/recommendations.csv")
    # per metric: size 2 (both ensembles), the spp bands low, medium, high, overall best, second, fewer
    scopes = [("size", "2"), ("band", "low"), ("band", "medium"), ("band", "high"), ("overall", "best"),
              ("overall", "second"), ("overall", "fewer")]
    assert list(zip(rec["metric"], rec["scope"], rec["key"].astype(str))) == [(m, *s) for m in METRICS for s in scopes]
    # (scope, key) -> the ranking column the pick is scored on and the place it holds
    picks = {("size", "2"): ("Avg.", 1), ("band", "low"): ("4", 1), ("band", "medium"): ("64", 1),
             ("overall", "best"): ("Avg.", 1), ("overall", "second"): ("Avg.", 2), ("overall", "fewer"): ("Avg.", 1)}
    for metric in METRICS:
        ranking = pd.read_csv(results / f"tables/ranking_{metric}.csv").set_index("candidate")
        for row in rec[rec["metric"] == metric].itertuples():
            if (row.scope, str(row.key)) == ("band", "high"):
                assert pd.isna(row.ours) and row.note == "no spp of the band in our data"
                continue
            column, place = picks[row.scope, str(row.key)]
            assert row.ours in PAIRS and row.candidates == 2, row
            assert row.ours_id == POOL_IDS[POOL_SLICE.index(row.ours)], row
            other = next(name for name in PAIRS if name != row.ours)
            assert row.ours_score == pytest.approx(ranking.loc[row.ours, column], abs=2 * SCORE_TOL), row
            better = row.ours_score >= ranking.loc[other, column] - 2 * SCORE_TOL
            assert better if place == 1 else row.ours_score <= ranking.loc[other, column] + 2 * SCORE_TOL, row
            assert 0 <= row.ours_fraction <= 1, row
    _assert_within(rec["ours_ci_low"], rec["ours_score"], rec["ours_ci_high"], tol=2e-4, what="recommendations")
    both = pd.read_csv(results / "tables/study/recommendations_metrics.csv")
    assert set(both["set"]) == {"all", "paper-named"}
    chosen = both.dropna(subset=["combined"])
    assert set(chosen["combined"]) <= set(PAIRS) and chosen["combined_fraction"].between(0, 1).all()
    _assert_within(chosen["combined_ci_low"], chosen["combined_score"], chosen["combined_ci_high"], tol=2e-4,
                   what="recommendations_metrics")
    # the relMSE pick among every ensemble is recommendations.csv's
    relmse = rec[rec["metric"] == "relmse"]
    mine = relmse.set_index(["scope", relmse["key"].astype(str)])["ours"]
    for row in chosen[chosen["set"] == "all"].itertuples():
        assert row.relmse == mine[row.scope, str(row.key)], row


def test_study_pair_members_recount_the_wins_from_metrics(results, metrics):
    pairs = pd.read_csv(results / "tables/study/pair_members.csv", dtype={"spp": str, "failures": str})
    expected = [(metric, ensemble, member, spp) for metric in METRICS for ensemble, members in PAIRS.items()
                for member in [*members, "both"] for spp in ["4", "64", "all"]]
    assert list(zip(pairs["metric"], pairs["ensemble"], pairs["member"], pairs["spp"])) == expected
    for metric in METRICS:
        values = _wide(metrics, metric)
        for row in pairs[pairs["metric"] == metric].itertuples():
            chosen = values if row.spp == "all" else values.xs(int(row.spp), level="spp", drop_level=False)
            members = PAIRS[row.ensemble] if row.member == "both" else [row.member]
            wins = (chosen[row.ensemble].to_numpy()[:, None] < chosen[members].to_numpy()).all(axis=1)
            assert (row.cases, row.wins) == (len(chosen), int(wins.sum())), row
            assert row.fraction == pytest.approx(wins.mean(), abs=1e-4), row
            lost = [f"{scene}@{spp}" for (scene, spp), won in zip(chosen.index, wins) if not won]
            assert sorted(("" if pd.isna(row.failures) else row.failures).split()) == sorted(lost), row
    _assert_within(pairs["ci_low"], pairs["fraction"], pairs["ci_high"], tol=2e-4, what="pair_members")
    assert pairs[["ci_low", "ci_high"]].stack().between(0, 1).all()
    assert set(pairs["verdict"]) <= {"reproduced", "not reproduced", "inconclusive"}


def test_study_findings_have_verdicts_and_intervals(results):
    findings = pd.read_csv(results / "tables/study/findings.csv")
    assert set(findings["metric"]) == set(METRICS)
    for metric in METRICS:
        assert {"a", "b"} <= set(findings.loc[findings["metric"] == metric, "finding"]), metric
    assert set(findings["verdict"].dropna()) <= {"reproduced", "not reproduced", "inconclusive"}
    assert findings["claim"].notna().all() and findings["quantity"].notna().all()
    _assert_within(findings["ci_low"], findings["estimate"], findings["ci_high"], tol=2e-4, what="findings")
    # an interval decides a verdict by its side of the threshold: reproduced "gain" rows lie above 0
    gains = findings[findings["quantity"].str.startswith("gain size") & (findings["verdict"] == "reproduced")]
    assert (gains["ci_low"] > 0).all(), gains


def test_study_paper_table3_and_reference_noise_agree_with_the_rankings(results):
    from mcbench.analysis.pool import PAPER_TABLE3

    paper = pd.read_csv(results / "tables/study/paper_table3.csv", dtype={"spp": str})
    assert sorted(set(paper["id"])) == sorted(PAPER_TABLE3)         # the paper's rows, ours beside them
    ranking = pd.read_csv(results / "tables/ranking_relmse.csv").set_index("candidate")
    ours = paper.dropna(subset=["ours"])
    # the bases of our pool slice are in the paper's Table 3 (its ensembles #10, #15 are not)
    assert set(ours["candidate"]) == {"kpcn", "nfor", "oidn", "rdfc"}
    assert set(ours["spp"]) == {"4", "64", "Avg.", "Avg. (common spp)"}
    for row in ours[ours["spp"].isin(["4", "64", "Avg."])].itertuples():
        assert row.ours == pytest.approx(ranking.loc[row.candidate, row.spp], abs=2 * SCORE_TOL), row
    both = paper.dropna(subset=["ours", "paper"])
    np.testing.assert_allclose(both["difference"], both["ours"] - both["paper"], atol=2e-4)
    assert (paper.loc[~paper["candidate"].isin(POOL_SLICE), "note"].str.endswith("not in our ranking")).all()
    assert paper.loc[~paper["candidate"].isin(POOL_SLICE), "ours"].isna().all()

    noise = pd.read_csv(results / "tables/study/reference_noise.csv", dtype={"spp": str, "changed": str})
    assert list(noise["spp"]) == ["4", "64", "Avg."]
    assert noise["kendall_tau"].between(-1, 1).all()
    changed = noise["changed"].fillna("").str.split()
    assert list(noise["real_changes"]) == [len(c) for c in changed]
    assert list(noise["agree"]) == ["yes" if not c else "no" for c in changed]
    corrected = pd.read_csv(results / "tables/ranking_relmse_corrected.csv").set_index("candidate")
    for row in noise.itertuples():
        for column, table in (("top_raw", ranking), ("top_corrected", corrected)):
            top = getattr(row, column).split()
            assert len(top) == 3 and set(top) <= set(RANKED), row
            # the top three by mean score, best first
            scores = table.loc[top, row.spp].to_numpy()
            assert (np.diff(scores) <= 2 * SCORE_TOL).all(), (column, row)
            assert scores[-1] >= table[row.spp].drop(top).max() - 2 * SCORE_TOL, (column, row)


@pytest.mark.parametrize("metric", METRICS)
def test_study_figures_decode_at_their_size(results, metric):
    figures = results / "figures/study"
    _assert_png(figures / f"score_size_{metric}.png", inches=(7.2, 4.8))
    _assert_png(figures / f"speed_score_{metric}.png", inches=(9.6, 5.4))
    _assert_png(figures / f"equal_time_{metric}.png", inches=(8.6, 4.8))
    # score curves: a row of height per entry, 4.2 inches at least
    _assert_png(figures / f"score_curves_{metric}.png", inches=(11.5, max(4.2, 0.16 * len(RANKED) + 1.0)))
    # error curves: one 2.9-inch panel per scene and the mean over scenes
    _assert_png(figures / f"error_curves_{metric}.png", width_inches=2.9 * 4)


# --- comparisons (results/tables/comparisons) ---------------------------------------------------

@pytest.mark.parametrize("metric", METRICS)
def test_comparison_tables_1_and_2_recount_the_wins_from_metrics(results, metrics, metric):
    values = _wide(metrics, metric)
    # the one full ensemble with one-hot variants (ensemble, of oidn and jbf): 3 scenes per spp
    for number, rivals in ((1, ["onehot_sbf", "onehot_nfor"]), (2, ["onehot_post"])):
        table = pd.read_csv(results / f"tables/comparisons/table{number}_{metric}.csv", dtype={"size": str, "spp": str})
        assert list(table.columns) == ["size", "spp", "cases", "wins", "percent"]
        assert list(zip(table["size"], table["spp"])) == [(size, spp) for size in ("2", "Avg.")
                                                          for spp in ("4", "64", "Avg.")]
        wins = values["ensemble"] < values[rivals].min(axis=1)
        for row in table.itertuples():
            chosen = wins if row.spp == "Avg." else wins.xs(int(row.spp), level="spp")
            assert (row.cases, row.wins) == (len(chosen), int(chosen.sum())), (number, row)
            assert row.percent == pytest.approx(100 * chosen.mean(), abs=1e-4), (number, row)
        text = (results / f"tables/comparisons/table{number}_{metric}.md").read_text()
        assert text.startswith(f"# Table {number} (")
        assert "Not in this table (variant set incomplete)" in text   # the pool's ensembles have no variants


def test_ablation_table_compares_each_ablation_with_its_full_ensemble(results, metrics, timings):
    table = pd.read_csv(results / "tables/comparisons/ablations.csv", dtype={"spp": str}, keep_default_na=False,
                        na_values=[""])                                 # "n/a" is a value of reproduced
    kinds = {"unconstrained weights": "ensemble_unconstrained", "exact solver": "ensemble_exact",
             "naive averaging": "naive"}
    assert list(zip(table["kind"], table["spp"])) == [(k, s) for k in kinds for s in ("4", "64", "Avg.")]
    relmse, dssim = _wide(metrics, "relmse"), _wide(metrics, "dssim")
    seconds = timings.pivot_table(index=["scene", "spp"], columns="method", values="seconds")
    for row in table.itertuples():
        ablation = kinds[row.kind]

        def of_spp(frame):
            return frame if row.spp == "Avg." else frame.xs(int(row.spp), level="spp")

        r, d, s = of_spp(relmse), of_spp(dssim), of_spp(seconds)
        assert row.cases == len(r), row
        for value, expected in ((row.relmse_ablation, r[ablation].mean()), (row.relmse_full, r["ensemble"].mean()),
                                (row.dssim_ablation, d[ablation].mean()), (row.dssim_full, d["ensemble"].mean()),
                                (row.loses, (r[ablation] > r["ensemble"]).mean()),
                                (row.time_ratio, (s[ablation] / s["ensemble"]).mean())):
            assert value == pytest.approx(expected, rel=1e-5, abs=1e-12), row
        assert row.reproduced == ("n/a" if row.kind == "exact solver" else
                                  "yes" if row.loses >= 0.5 and row.relmse_ablation > row.relmse_full else "no"), row
    text = (results / "tables/comparisons/ablations.md").read_text()
    assert "unconstrained weights (5.2.1)" in text and "naive averaging (5.2.5)" in text
    assert len(_markdown_rows(text.split("Rules of")[0])) == len(table)


@pytest.mark.parametrize("metric", METRICS)
def test_comparison_ranking_scores_the_comparison_methods_with_their_ensemble(results, metrics, metric):
    table = pd.read_csv(results / f"tables/comparisons/ranking_{metric}.csv")
    assert list(table.columns) == ["candidate", "role", "compared_with", "4", "64", "Avg."]
    roles = {"ensemble": "full ensemble", "ensemble_exact": "exact solver", "onehot_sbf": "one-hot sbf",
             "onehot_nfor": "one-hot nfor", "onehot_post": "one-hot post", "naive": "naive average",
             "ensemble_unconstrained": "unconstrained weights", "noisy": "noisy"}
    assert sorted(table["candidate"]) == sorted(roles)
    table = table.set_index("candidate")
    assert table["role"].to_dict() == roles
    assert table["compared_with"].fillna("").to_dict() == {n: "" if n in ("ensemble", "noisy") else "ensemble"
                                                           for n in roles}
    assert table["Avg."].is_monotonic_decreasing, table                # best first
    expected = _mean_scores(_wide(metrics, metric), list(roles))
    for column in (4, 64, "Avg."):
        np.testing.assert_allclose(table[str(column)], expected.loc[table.index, column], atol=SCORE_TOL)
    # kept out of the main ranking
    assert not (set(roles) - {"noisy"}) & set(pd.read_csv(results / f"tables/ranking_{metric}.csv")["candidate"])


# --- progressive denoising (results/tables/progressive, results/progressive) ---------------------

def test_progressive_consistency_recounts_the_exceptions_from_metrics(results, metrics):
    consistency = pd.read_csv(results / "tables/progressive/consistency.csv")
    assert list(consistency["spp"]) == SPPS and set(consistency["entry"]) == {"pd_oidn"}
    assert set(consistency["input"]) == {"oidn"}
    relmse = _wide(metrics, "relmse")
    for row in consistency.itertuples():
        case = relmse.xs(row.spp, level="spp")
        x, z, y = case["noisy"], case["pd_oidn"], case["oidn"]
        assert (row.cases, row.worse, row.input_worse) == (3, int((z > x).sum()), int((y > x).sum())), row
        for value, expected in ((row.noisy, x.mean()), (row.value, z.mean()), (row.input_value, y.mean()),
                                (row.gap, (z - x).abs().mean()), (row.ratio, np.exp(np.log(z / x).mean())),
                                (row.input_ratio, np.exp(np.log(y / x).mean()))):
            assert value == pytest.approx(expected, rel=1e-5), row


def test_progressive_per_spp_holds_each_entrys_means(results, metrics, timings):
    per_spp = pd.read_csv(results / "tables/progressive/per_spp.csv")
    assert list(per_spp.columns) == ["entry", "4", "64", "avg", "quantity"]
    # noisy, then the input followed by its progressive entry; errors of relMSE and SMAPE, then the
    # seconds of the methods (the noisy input has none)
    assert list(zip(per_spp["quantity"], per_spp["entry"])) == [
        (q, e) for q in ("relmse", "smape") for e in ("noisy", "oidn", "pd_oidn")] + [
        ("seconds", "oidn"), ("seconds", "pd_oidn")]
    own = timings.pivot_table(index=["scene", "spp"], columns="method", values="seconds")
    for row in per_spp.to_dict("records"):
        values = own if row["quantity"] == "seconds" else _wide(metrics, row["quantity"])
        means = values[row["entry"]].groupby(level="spp").mean()
        np.testing.assert_allclose([row["4"], row["64"], row["avg"]], [means[4], means[64], means.mean()],
                                   rtol=1e-5, err_msg=str(row))
    assert (per_spp[["4", "64", "avg"]] > 0).all().all()


def test_progressive_curve_has_every_entry_per_spp_and_its_figure(smoke_run, results):
    _, config = smoke_run
    folder = results / f"progressive/{config['scenes'][0]}"
    curve = pd.read_csv(folder / "curve.csv")
    entries = list(dict.fromkeys(curve["entry"]))
    assert len(entries) == 4 and entries[0] == "noisy"            # noisy, base, PD, the t-test bound
    assert list(zip(curve["spp"], curve["entry"])) == [(spp, e) for spp in (4, 16) for e in entries]
    errors = curve[["relmse", "smape"]].to_numpy()
    assert np.isfinite(errors).all() and (errors >= 0).all() and (curve["smape"] <= 1).all()
    assert (curve["seconds"] > 0).all()
    _assert_png(folder / "curve.png", inches=(11, 4.4))


# --- the oracle study (results/oracle) --------------------------------------------------------

def test_oracle_table_has_the_nine_panels_and_the_weight_maps(smoke_run, results):
    _, config = smoke_run
    folder = results / f"oracle/{config['scenes'][0]}"
    oracle = pd.read_csv(folder / "table.csv")
    assert list(oracle.columns) == ["name", "panel", "statistics", "weights", "relmse", "dssim"]
    panels = [f"gt_{statistics}_{solve}" for statistics in ("full", "half")
              for solve in ("one_hot", "unconstrained", "simplex")] + ["dual_one_hot", "dual_unconstrained",
                                                                       "dual_ensemble"]
    bases = config["oracle"]["denoisers"]
    assert list(oracle["name"]) == panels + ["noisy", *bases]
    assert list(oracle["panel"]) == list("abcdefghi") + ["-"] * (1 + len(bases))
    assert np.isfinite(oracle[["relmse", "dssim"]].to_numpy()).all()
    assert (oracle["relmse"] >= 0).all() and oracle["dssim"].between(0, 2).all(), oracle
    assert len(_markdown_rows((folder / "table.md").read_text())) == len(oracle)
    # one row per base denoiser, one column per panel (mcbench.analysis.oracle_tables.weight_maps_figure)
    _assert_png(folder / "weights.png", inches=(1.7 * 9 + 1.6, 1.7 * len(bases) + 1.2))


# --- timings and benchmark records ------------------------------------------------------------

def test_timings_hold_one_positive_row_per_method_run(smoke_run, results, timings):
    _, config = smoke_run
    assert {"scene", "spp", "method", "seconds", "width", "height"} <= set(timings.columns)
    keys = list(zip(timings["scene"], timings["spp"], timings["method"]))
    assert len(keys) == len(set(keys))
    assert set(keys) == {(s, n, m) for s in config["scenes"] for n in SPPS for m in POOL_SLICE + EXTRAS}
    assert (timings["seconds"] > 0).all() and np.isfinite(timings["seconds"]).all(), timings[timings["seconds"] <= 0]
    assert (timings[["width", "height"]] == 32).all().all()
    assert list(keys) == sorted(keys, key=lambda k: (k[2], k[0], k[1]))   # sorted by method, scene, spp
    # one job per case made every method and evaluation of the case, with its log
    logs = sorted((results / "logs/cases").rglob("*.log"))
    assert len(logs) == 3 * 2, logs


# --- the report's figures (results/figures) -------------------------------------------------

def test_report_figures_decode_at_their_size(results):
    for metric in METRICS:
        # one 2.9-inch panel per scene and the mean over scenes
        _assert_png(results / f"figures/error_{metric}.png", width_inches=2.9 * 4)
    _assert_png(results / "figures/speed_error.png", inches=(6.4, 4.6))
    _assert_png(results / "figures/gallery.png")


def test_manifest_describes_the_run_and_is_newer_than_its_tables(smoke_run, results):
    from mcbench.analysis.study.markdown import PROVENANCE_HEADING
    from mcbench.io.tables import read_json
    from mcbench.pipeline.config import config_digest, resolve_config

    _, config = smoke_run
    manifest = read_json(results / "manifest.json")
    assert list(manifest) == ["config_digest", "cpu", "git", "manifest_version", "platform", "references", "versions"]
    assert manifest["config_digest"] == config_digest(resolve_config(config))
    assert set(manifest["versions"]) == {"mitsuba", "drjit", "oidn", "torch", "numpy", "scipy", "flip_evaluator",
                                         "snakemake", "python", "mcbench"}
    assert manifest["cpu"]["logical_cores"] == os.cpu_count()
    # this checkout's HEAD, or (a smoke folder reused through $MCBENCH_TEST_SMOKE_DIR: a new commit
    # alone reruns nothing) one of its ancestors
    commit = manifest["git"]["commit"]
    if subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True).returncode == 0:
        assert subprocess.run(["git", "-C", str(REPO), "merge-base", "--is-ancestor", commit, "HEAD"]).returncode == 0
    else:
        assert commit == "unknown"
    described = [results / "metrics.csv", results / "timings.csv",
                 *(results / f"tables/{kind}_{m}.csv" for kind in ("ranking", "extras") for m in METRICS)]
    assert all((results / "manifest.json").stat().st_mtime >= p.stat().st_mtime for p in described)
    summary = (results / "tables/study/summary.md").read_text()
    block = summary.split(f"\n{PROVENANCE_HEADING}\n\n")[1]
    assert f"- Commit: `{manifest['git']['commit']}`" in block and manifest["config_digest"] in block


def test_the_smoke_study_takes_its_references_from_the_store_and_says_so(results):
    """The repository's store holds the smoke study's references: the run copied and checked them
    (no reference chunk rendered), and its manifest (and so its bundle) says where each came from."""
    manifest = json.loads((results / "manifest.json").read_text())
    assert {scene: entry["source"] for scene, entry in manifest["references"].items()} == {
        "cornell_box": "store", "envmap_objects": "store", "glass_caustics": "store"}
    for scene in manifest["references"]:
        assert json.loads((results / "references" / f"{scene}.check.json").read_text())["passed"] is True
    assert not list((results / "references").glob("*/chunk*.exr"))


def test_rerun_has_nothing_to_do(smoke_run):
    workdir, _ = smoke_run
    result = snakemake(workdir, "-n")
    assert "Nothing to be done" in result.stdout + result.stderr


def test_corrupt_render_stops_with_file_name_and_keeps_outputs(smoke_run, tmp_path):
    workdir = tmp_path / "corrupt"
    shutil.copytree(smoke_run[0], workdir, ignore=shutil.ignore_patterns(".snakemake"))
    render = workdir / "results/renders/cornell_box/spp4.exr"
    render.write_bytes(render.read_bytes()[:200])
    kept = sorted((workdir / "results/outputs/glass_caustics/spp64").glob("*.exr"))[0]   # an output a method reads
    kept_mtime = kept.stat().st_mtime_ns
    # the case whose render is newer than its outputs runs again and reads the corrupt render
    result = snakemake(workdir, "results/cases/cornell_box/spp4.json", check=False)
    assert result.returncode != 0
    assert "renders/cornell_box/spp4.exr" in result.stdout + result.stderr
    assert kept.stat().st_mtime_ns == kept_mtime


def test_the_export_of_a_case_makes_the_outputs_its_job_removed(smoke_run, tmp_path):
    """keep_outputs read: the case job removed the outputs no method reads (the ensemble's); the
    export of that case (rule export_case) makes them again, with the pixels a kept output has,
    and the study is still finished after it."""
    from mcbench.io.exr import read_layers

    workdir = tmp_path / "export"
    shutil.copytree(smoke_run[0], workdir, symlinks=True)
    outputs = workdir / "results/outputs/glass_caustics/spp64"
    assert not (outputs / "ensemble.exr").exists() and (outputs / "ensemble.json").exists()
    snakemake(workdir, "results/export/glass_caustics/spp64")
    exported = workdir / "results/export/glass_caustics/spp64"
    assert (outputs / "ensemble.exr").exists() and any(exported.rglob("*ensemble*"))
    kept = workdir / "kept"
    shutil.copytree(smoke_run[0], kept, symlinks=True)
    config = yaml.safe_load((kept / "config.yaml").read_text())
    (kept / "config.yaml").write_text(yaml.safe_dump({**config, "keep_outputs": "all"}))
    snakemake(kept, "results/cases/glass_caustics/spp64.json")
    np.testing.assert_array_equal(read_layers(outputs / "ensemble.exr")["color"],
                                  read_layers(kept / "results/outputs/glass_caustics/spp64/ensemble.exr")["color"])
    assert "Nothing to be done" in snakemake(workdir, "-n").stdout + snakemake(workdir, "-n").stderr


def test_nan_render_is_refused_naming_file_and_count(smoke_run, tmp_path):
    from mcbench.io.exr import read_layers, write_layers

    workdir = tmp_path / "nan"
    shutil.copytree(smoke_run[0], workdir, ignore=shutil.ignore_patterns(".snakemake"))
    render = workdir / "results/renders/envmap_objects/spp64.exr"
    layers = read_layers(render)
    layers["color_a"][:] = np.nan
    write_layers(render, layers, metadata={"spp": 64})
    result = snakemake(workdir, "results/cases/envmap_objects/spp64.json", check=False)
    text = result.stdout + result.stderr
    assert result.returncode != 0
    assert "renders/envmap_objects/spp64.exr" in text and "1024 pixel(s) with NaN/Inf" in text


def test_unknown_method_is_named_before_any_job(tmp_path):
    workdir = tmp_path / "unknown"
    write_config(workdir, denoisers=["oidn", "nfro"])
    result = snakemake(workdir, "-n", check=False)
    text = result.stdout + result.stderr
    assert result.returncode != 0
    assert "denoisers[1]" in text and "nfro" in text
    assert not (workdir / "results").exists()


def test_invalid_config_is_refused(tmp_path):
    workdir = tmp_path / "invalid"
    write_config(workdir, spp=[4, 7])
    result = snakemake(workdir, "-n", check=False)
    assert result.returncode != 0 and "7" in result.stdout + result.stderr


@pytest.mark.extended     # 100 s; the fuzz tier's random kills (test_interruptions.py) cover every stage too
def test_killed_run_resumes_without_redoing_finished_jobs(tmp_path):
    workdir = tmp_path / "resume"
    write_config(workdir, scenes=["cornell_box", "envmap_objects"])
    renders = [f"results/renders/{s}/spp{n}.exr" for s in ("cornell_box", "envmap_objects") for n in (4, 64)]
    snakemake(workdir, *renders)
    mtimes = {r: (workdir / r).stat().st_mtime_ns for r in renders}
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(workdir),
               "--configfile", str(workdir / "config.yaml"), "--cores", "2"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and not list((workdir / "results/outputs").glob("*/*/*.json")):
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    finished = {p: p.stat().st_mtime_ns for p in (workdir / "results/outputs").glob("*/*/*.json")}
    assert finished, "no method finished before the kill"
    # A hard kill leaves Snakemake's lock behind; unlocking is the documented first step.
    snakemake(workdir, "--unlock")
    result = snakemake(workdir, "--rerun-incomplete")
    assert not re.search(r"^(local)?rule render_noisy:", result.stdout + result.stderr, re.MULTILINE)
    assert re.search(r"^(local)?rule run_case:", result.stdout + result.stderr, re.MULTILINE)
    for render, mtime in mtimes.items():
        assert (workdir / render).stat().st_mtime_ns == mtime, f"{render} was redone"
    # the methods finished before the kill are kept by the killed case's job when it runs again
    # (their records' keys match): not made again
    for path, mtime in finished.items():
        assert path.stat().st_mtime_ns == mtime, f"{path} was made again"
    assert (workdir / "results/tables/ranking_relmse.csv").exists()


def test_notebook_executes_headless_on_results(smoke_run, monkeypatch):
    """The whole notebook, run by a Jupyter kernel (nbclient) as a user would, on real results."""
    import nbformat
    from nbclient import NotebookClient

    workdir, _ = smoke_run
    monkeypatch.setenv("MCBENCH_RESULTS", str(workdir / "results"))
    notebook = nbformat.read(REPO / "workflow/notebooks/explore.ipynb", as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO / "workflow/notebooks")}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o["data"]["image/png"] for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 5                                   # curves, scatter, images, weights
    for image in images:
        _assert_png(io.BytesIO(base64.b64decode(image)))
    text = "".join(o.get("text", "") for o in outputs)
    assert "# Ranking by relmse" in text and "no combiner with weight maps" not in text


def test_training_data_target_writes_reproducible_disjoint_crops(tmp_path):
    from mcbench.io.exr import read_layers, read_metadata

    # the smoke config's learned combiner (progressive) trains on a subset of these scenes
    training = {"first_seed": 3, "count": 2, "fibre_count": 0, "resolution": [32, 24], "crop": 12, "crops": 2,
                "spp": [4, 16], "target_spp": 64, "combiners": {"count": 2, "fibre_count": 0, "crops": 2}}
    workdir = tmp_path / "training"
    write_config(workdir, training=training)
    snakemake(workdir, "training_data")
    paths = sorted((workdir / "results/training").glob("example_*.exr"))
    assert [p.name for p in paths] == ["example_3_0.exr", "example_3_1.exr", "example_4_0.exr", "example_4_1.exr"]
    boxes = []
    for path in paths[:2]:
        layers = read_layers(path)
        assert {"color_spp4", "color_a_spp16", "target", "target_variance"} <= set(layers)
        assert layers["target"].shape == (12, 12, 3)
        assert all(np.isfinite(v).all() for v in layers.values())
        boxes.append([int(v) for v in read_metadata(path)["crop_box"].split(",")])
    (x0, y0, x1, y1), (u0, v0, u1, v1) = boxes
    assert x1 <= u0 or u1 <= x0 or y1 <= v0 or v1 <= y0, "crops of one image overlap"
    first = read_layers(paths[0])["color_spp4"]
    (workdir / "results/training" / paths[0].name).unlink()
    snakemake(workdir, "training_data")
    np.testing.assert_array_equal(read_layers(paths[0])["color_spp4"], first)


def test_paper_config_dry_runs_with_all_30_scenes(tmp_path):
    workdir = tmp_path / "paper"
    workdir.mkdir()
    (workdir / "config.yaml").write_text((REPO / "workflow/configs/paper.yaml").read_text())
    result = snakemake(workdir, "-n")
    text = result.stdout + result.stderr
    scenes = yaml.safe_load((REPO / "workflow/configs/paper.yaml").read_text())["scenes"]
    assert len(scenes) == 30
    for scene in scenes:
        assert f"results/references/{scene}.exr" in text
    counts = {line.split()[0]: int(line.split()[1]) for line in text.splitlines()
              if len(line.split()) == 2 and line.split()[1].isdigit()}
    assert counts["render_noisy"] == 30 * 9
    assert counts["merge_reference"] == 30


def test_train_rule_trains_missing_weights_and_the_main_job_never_retrains(tmp_path):
    import json

    import torch

    weights = tmp_path / "weights"
    training = {"first_seed": 6, "count": 2, "fibre_count": 0, "resolution": [32, 24], "crop": 12, "crops": 2,
                "spp": [4, 16],
                "target_spp": 64,
                "combiners": {"count": 2, "fibre_count": 0, "crops": 2},   # the smoke config's progressive
                "networks": {"wskpn": {"steps": 3, "batch_size": 2, "patch": 12, "validate_every": 3,
                                       "checkpoint_every": 3}}}
    workdir = tmp_path / "train"
    write_config(workdir, training=training, weights_dir=str(weights), denoisers=["oidn", "jbf", "wskpn"],
                 study={"pool": False})      # no pool: its learned bases have no weights in this folder
    weights.mkdir(exist_ok=True)                   # the smoke config's progressive: the committed weights
    for suffix in (".pt", ".json"):
        shutil.copy(REPO / "methods/weights" / f"progressive{suffix}", weights / f"progressive{suffix}")
    snakemake(workdir, "train_wskpn")
    blob = torch.load(weights / "wskpn.pt", weights_only=True)
    assert set(blob) == {"arch", "state_dict"}
    record = json.loads((weights / "wskpn.json").read_text())
    assert record["settings"]["steps"] == 3 and record["data"]["training_scenes"] == [6]
    assert record["data"]["validation_scenes"] == [7]
    assert (workdir / "results/logs/training/train_wskpn.log").exists()
    # Newer training data does not make the main job retrain: it uses the weights as they are.
    for crop in (workdir / "results/training").glob("*.exr"):
        os.utime(crop, (time.time() + 60, time.time() + 60))
    text = "".join(snakemake(workdir, "-n").stdout.splitlines(keepends=True))
    assert "train_network" not in text and "run_case" in text
    snakemake(workdir, "results/cases/cornell_box/spp4.json")
    timing = json.loads((workdir / "results/outputs/cornell_box/spp4/wskpn.json").read_text())
    assert timing["method"] == "wskpn" and timing["seconds"] > 0
    # Nor does a checkout without training data (a clean clone): no crops, no training planned;
    # and an explicit train_<name> with the weights present has nothing to do.
    shutil.rmtree(workdir / "results/training")
    text = snakemake(workdir, "-n").stdout
    assert "training_example" not in text and "train_network" not in text and "run_case" in text
    assert "train_network" not in snakemake(workdir, "-n", "train_wskpn").stdout
    # New weights rerun the method (their digest is a parameter), still without training.
    torch.save(blob | {"state_dict": {k: v + 0.01 if v.is_floating_point() else v
                                      for k, v in blob["state_dict"].items()}}, weights / "wskpn.pt")
    text = snakemake(workdir, "-n", "results/cases/cornell_box/spp4.json").stdout
    assert "run_case" in text and "train_network" not in text
    # Without weights the main job stops, naming the folder (it never plans training itself);
    # train_<name> plans the training again.
    (weights / "wskpn.pt").unlink()
    result = snakemake(workdir, "-n", "results/cases/cornell_box/spp64.json", check=False)
    assert result.returncode != 0 and f"no weights for wskpn in {weights}" in result.stdout + result.stderr
    assert "train_network" in snakemake(workdir, "-n", "train_wskpn").stdout



def test_a_base_trained_here_is_not_trained_again_for_its_combiners_training(tmp_path):
    """The documented retraining order: train_kpcn, then train_deep_combiner (which learns from
    KPCN's results). The second run takes the weights the first made as they are, under the
    project's profile and under Snakemake's own default rerun triggers too (``--workflow-profile
    none``, or a command line naming them): with the ``input`` trigger, a training job whose
    recorded inputs differ from the planned ones would run again, and Snakemake deletes a job's
    outputs (hours of training) before it runs."""
    weights = tmp_path / "weights"
    training = {"first_seed": 6, "count": 2, "fibre_count": 0, "resolution": [32, 24], "crop": 16, "crops": 2,
                "spp": [4, 16], "target_spp": 64, "combiners": {"count": 2, "fibre_count": 0, "crops": 2},
                "networks": {name: {"steps": 2, "batch_size": 2, "patch": 16, "validate_every": 2,
                                    "checkpoint_every": 2} for name in ("kpcn", "deep_combiner")}}
    workdir = tmp_path / "train"
    write_config(workdir, training=training, weights_dir=str(weights), denoisers=["nfor", "oidn", "kpcn"],
                 combiners=[{"name": "kpcn_dc", "method": "deep_combiner", "inputs": ["kpcn"]}],
                 study={"pool": False})
    snakemake(workdir, "train_kpcn")
    trained = (weights / "kpcn.pt").read_bytes()
    for triggers in ([], ["--rerun-triggers", "mtime", "params", "input", "software-env", "code"]):
        text = snakemake(workdir, "-n", *triggers, "--", "train_deep_combiner").stdout
        assert "train_network" not in text, text[-3000:]
        assert "training_correlated" in text and "train_combiner" in text
        assert "train_network" not in snakemake(workdir, "-n", *triggers, "--", "train_kpcn").stdout
    snakemake(workdir, "train_deep_combiner")
    assert (weights / "kpcn.pt").read_bytes() == trained and (weights / "deep_combiner.pt").exists()
    # KPCN retrained (new weights), the combiner's weights deleted to train it again: only KPCN's
    # results on the crops are made again (the weights' digest is their parameter), then the combiner
    (weights / "kpcn.pt").write_bytes(trained + b"retrained")
    (weights / "deep_combiner.pt").unlink()
    text = snakemake(workdir, "-n", "train_deep_combiner").stdout
    planned = {rule: int(n) for rule, n in re.findall(r"^(\w+)\s+(\d+)$", text, flags=re.MULTILINE)}
    assert "train_network" not in planned and planned.get("train_combiner") == 1, text[-3000:]
    assert planned.get("training_correlated") == 2 and "base=nfor" not in text and "base=oidn" not in text

# --- the DAG is parsed the same way from anywhere, and mistakes stop before any job ----------

def _dry_run(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-n", "--nolock", *args]
    return subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=300)


def _planned(result: subprocess.CompletedProcess) -> tuple[list[str], str]:
    """The planned (rule, output) lines and the config digest line of a dry run."""
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    lines = text.splitlines()
    jobs = sorted(line.strip() for line in lines if line.strip().startswith("output:"))
    digest = [line for line in lines if "mcbench: configuration" in line]
    assert len(digest) == 1, text[-2000:]
    return jobs, digest[0].split("digest ")[1]


def test_the_same_command_plans_the_same_study_from_any_folder(tmp_path):
    """From the repository root the smoke config once inherited config.yaml's per-scene reference
    spp (65536 instead of 1024), from another folder it did not: the same jobs and the same
    resolved configuration (digest) from both, including a folder with a space in its name.
    ``--forceall``: every job is planned whatever the checkout's results/ already holds (after
    the README's main job, the root's results/ is complete and the other folder's is empty)."""
    other = tmp_path / "a folder with spaces"
    other.mkdir()
    from_root = _planned(_dry_run(REPO, "--configfile", str(SMOKE), "--forceall"))
    from_other = _planned(_dry_run(other, "--configfile", str(SMOKE), "--forceall"))
    assert from_root == from_other and len(from_root[0]) > 40
    from mcbench.pipeline.config import config_digest, resolve_config

    assert from_root[1] == config_digest(resolve_config(yaml.safe_load(SMOKE.read_text())))
    # without --configfile the default study (config.yaml) is read from the checkout, not the folder
    default_root = _planned(_dry_run(REPO, "--forceall"))
    default_other = _planned(_dry_run(other, "--forceall"))
    assert default_root == default_other
    assert default_root[1] == config_digest(resolve_config(yaml.safe_load((REPO / "config.yaml").read_text())))


def _job_counts(result: subprocess.CompletedProcess) -> dict[str, int]:
    """The dry run's job-stats table as {rule: count}."""
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    table = text.split("Job stats:")[1].split("total")[0]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", table, re.MULTILINE)}


def test_the_manifest_is_planned_after_the_tables_and_read_by_the_summary_alone(tmp_path):
    """results/manifest.json is written after the tables it describes (metrics, timings, ranking
    and extras tables: its inputs) and only the study's tables and the `all` target take it, so
    writing it again never reruns anything else."""
    result = _dry_run(tmp_path, "--configfile", str(SMOKE))
    text = result.stdout + result.stderr
    assert result.returncode == 0, text[-3000:]
    inputs = {m.group(1): m.group(2).split(", ")
              for m in re.finditer(r"^(?:local)?rule (\w+):\n    input: (.*)$", text, re.MULTILINE)}
    assert {rule for rule, paths in inputs.items() if "results/manifest.json" in paths} == {"study_tables", "all"}
    assert {"results/metrics.csv", "results/timings.csv", "results/tables/ranking_relmse.csv",
            "results/tables/extras_relmse.csv"} <= set(inputs["provenance_manifest"])
    assert _job_counts(result)["provenance_manifest"] == 1


def test_each_case_is_one_job_and_parsing_writes_nothing(tmp_path):
    """One run_case job per case (mcbench.pipeline.cases: its methods, evaluations and tables),
    no per-method or per-entry job; a dry run writes nothing under the folder it plans in."""
    config = write_config(tmp_path, study={"pool": False})   # the config's methods only
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if ".snakemake" not in p.parts)
    result = _dry_run(tmp_path, "--configfile", str(tmp_path / "config.yaml"))
    counts, cases = _job_counts(result), len(config["scenes"]) * len(config["spp"])
    assert counts["run_case"] == cases, counts
    assert not {"run_method", "entry_metrics", "entry_viewer", "case_metrics", "viewer_case"} & set(counts)
    assert not any(rule.startswith("case_batch_") for rule in counts)
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if ".snakemake" not in p.parts)
    assert after == before                                     # no results/, no spec or batch file


def _rules(cwd: Path, configfile: Path) -> list[str]:
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--list-rules", "--nolock",
               "--configfile", str(configfile)]
    result = subprocess.run(command, capture_output=True, text=True, cwd=cwd, timeout=300)
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]
    return sorted(line.strip() for line in result.stdout.splitlines() if line.strip())


def test_the_rules_are_the_same_in_a_finished_study_and_an_empty_folder(smoke_run, tmp_path):
    """The rules and their names do not depend on what exists under results/: a finished study's
    folder and an empty one list the same rules (a SLURM job or a spawned job re-parses the
    workflow while other jobs are making files)."""
    workdir, _ = smoke_run
    empty = tmp_path / "empty"
    empty.mkdir()
    finished = _rules(workdir, workdir / "config.yaml")
    assert finished == _rules(empty, workdir / "config.yaml") and "run_case" in finished


def test_a_config_naming_only_scenes_runs(tmp_path):
    workdir = tmp_path / "narrow"
    workdir.mkdir()
    (workdir / "config.yaml").write_text("scenes: [cornell_box]\nresolution: [16, 16]\n")
    text = snakemake(workdir, "-n").stdout
    assert "results/references/cornell_box.exr" in text and "fog_beams" not in text
    snakemake(workdir, "results/cases/cornell_box/spp4.json")
    assert (workdir / "results/outputs/cornell_box/spp4/oidn.exr").exists()


@pytest.mark.parametrize("change, message", [
    ({"combiners": [{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"], "params": {"solvr": "exact"}}]},
     "combiners[0].params.solvr"),
    ({"combiners": [{"name": "ensemble", "method": "ensemble", "inputs": ["oidn", "jbf"], "params": {"solver": "exactt"}}]},
     "combiners[0].params.solver: 'exactt' is not allowed"),
    ({"denoisers": ["oidn", "noisy"]}, "denoisers[1].name: 'noisy' is reserved"),
    ({"spp": [4.0]}, "spp[0]: 4.0 is not of type 'integer'"),
    ({"resolution": [8, 8]}, "resolution"),
])
def test_config_mistakes_stop_at_parse_naming_the_key(tmp_path, change, message):
    workdir = tmp_path / "mistake"
    write_config(workdir, **change)
    result = snakemake(workdir, "-n", check=False)
    assert result.returncode != 0 and message in result.stdout + result.stderr
    assert not (workdir / "results").exists()


def test_a_mistyped_weights_dir_stops_instead_of_planning_training(tmp_path):
    workdir = tmp_path / "weights"
    write_config(workdir, weights_dir=str(tmp_path / "wieghts"))
    result = snakemake(workdir, "-n", check=False)
    text = result.stdout + result.stderr
    assert result.returncode != 0 and f"no weights for kpcn in {tmp_path / 'wieghts'}" in text
    assert "training_example" not in text


def test_the_workflow_profile_is_loaded_from_any_folder(tmp_path):
    text = _dry_run(tmp_path, "--configfile", str(SMOKE)).stderr
    assert f"Using workflow specific profile {REPO / 'profiles/default'}" in text


def test_parsing_the_dag_imports_no_torch_and_no_unnamed_method(tmp_path):
    """A dry run imports only the method modules the config names, and never torch."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import sys, runpy\n"
        "sys.argv = ['snakemake', '-s', sys.argv[1], '-n', '--nolock', '--configfile', sys.argv[2]]\n"
        "try:\n"
        "    runpy.run_module('snakemake', run_name='__main__')\n"
        "except SystemExit:\n"
        "    pass\n"
        "print('MODULES', sorted(m for m in sys.modules if m == 'torch' or m.startswith('methods.')))\n")
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({"scenes": ["cornell_box"], "denoisers": ["oidn", "kpcn"],
                                                          "combiners": [], "study": {"pool": False}}))
    result = subprocess.run([sys.executable, str(probe), str(REPO / "Snakefile"), str(tmp_path / "config.yaml")],
                            capture_output=True, text=True, cwd=tmp_path, timeout=300)
    line = [l for l in result.stdout.splitlines() if l.startswith("MODULES")]
    assert line, result.stdout[-2000:] + result.stderr[-2000:]
    # oidn, kpcn: the config's; jbf, rdfc: the oracle study's default bases (schema oracle.denoisers)
    assert line[0] == "MODULES ['methods.jbf', 'methods.kpcn', 'methods.oidn', 'methods.rdfc']"
