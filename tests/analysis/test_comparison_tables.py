"""Comparison tables (mcbench.analysis.comparison_tables): roles of methods, Tables 1-2, the ablation table and
the comparison ranking against tables computed by hand on a small synthetic study (2 scenes x
2 spp, full ensembles of sizes 2 and 3), the incomplete-variant and missing-case paths, and the
rule script run without Snakemake."""

from __future__ import annotations

import runpy
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.analysis.comparison_tables import (ablation_cases, ablation_table, beats_cases, beats_table,
                                                comparison_ranking, comparison_role, find_comparisons,
                                                write_ablation_table, write_comparison_ranking, write_onehot_tables)

ROOT = Path(__file__).resolve().parents[2]
SCENES, SPPS = ("s1", "s2"), (4, 8)
CASES = [(s, n) for s in SCENES for n in SPPS]


ROLES = {"ensemble": "ensemble", "one_hot": "one-hot selection", "naive_average": "naive average"}


def spec(module, inputs=(), **params):
    return {"module": module, "kind": "combiner" if inputs else "denoiser", "inputs": list(inputs),
            "params": params, "label": f"L-{module}-{'+'.join(inputs)}-{params}", "comparison_role": ROLES.get(module)}


METHODS = {
    "a": spec("oidn"), "b": spec("nfor"), "c": spec("rdfc"),
    "e2": spec("ensemble", ["a", "b"]),
    "e3": spec("ensemble", ["a", "b", "c"], seed=3),          # seed is no ablation
    "ebc": spec("ensemble", ["b", "c"]),                      # no variants at all
    "oh2_sbf": spec("one_hot", ["b", "a"], prefilter="sbf"),  # same set, other order
    "oh2_nfor": spec("one_hot", ["a", "b"], prefilter="nfor"),
    "oh2_post": spec("one_hot", ["a", "b"], prefilter="post"),
    "oh3_sbf": spec("one_hot", ["a", "b", "c"], prefilter="sbf"),
    "oh3_nfor": spec("one_hot", ["c", "b", "a"], prefilter="nfor"),
    "avg2": spec("naive_average", ["a", "b"]),
    "e2_unc": spec("ensemble", ["a", "b"], weights="unconstrained"),
    "e2_qp": spec("ensemble", ["a", "b"], solver="qp"),
    "e3_single": spec("ensemble", ["a", "b", "c"], channels="single"),
    "e3_raw": spec("ensemble", ["c", "a", "b"], filter=False),
}

# relMSE per case (s1/4, s1/8, s2/4, s2/8); DSSIM is relMSE / 10.
E2 = [1.0, 1.0, 1.0, 1.0]
RELMSE = {
    "noisy": [9.0, 9.0, 9.0, 9.0], "a": [4.0, 4.0, 4.0, 4.0], "b": [5.0, 5.0, 5.0, 5.0], "c": [6.0, 6.0, 6.0, 6.0],
    "e2": E2, "e3": [1.0, 1.0, 1.0, 1.0], "ebc": [1.0, 1.0, 1.0, 1.0],
    # e2 against sbf and nfor: win, lose (sbf lower), lose (nfor lower), lose (tie with sbf)
    "oh2_sbf": [2.0, 0.5, 3.0, 1.0], "oh2_nfor": [3.0, 3.0, 0.9, 3.0],
    # e2 against post: win, win, win, lose
    "oh2_post": [2.0, 2.0, 2.0, 0.1],
    "oh3_sbf": [2.0, 2.0, 2.0, 2.0], "oh3_nfor": [2.0, 2.0, 2.0, 2.0],
    "avg2": [3.0, 3.0, 3.0, 0.5],           # loses 3 of 4, higher mean
    "e2_unc": [2.0, 2.0, 2.0, 2.0],         # always worse
    "e2_qp": [1.01, 1.01, 1.01, 1.01],      # within 5 %, 10x slower
    "e3_single": [0.5, 0.5, 0.5, 0.5],      # always better: not reproduced
    "e3_raw": [2.0, 0.5, 2.0, 0.5],         # loses half, mean 1.25 > 1
}
SECONDS = {name: 1.0 for name in RELMSE}
SECONDS["e2_qp"] = 10.0


def metrics_frame(relmse=RELMSE, *, dssim=True) -> pd.DataFrame:
    rows = [(s, n, name, "relmse", values[i]) for name, values in relmse.items() for i, (s, n) in enumerate(CASES)]
    if dssim:
        rows += [(s, n, c, "dssim", v / 10) for s, n, c, _, v in list(rows)]
    return pd.DataFrame(rows, columns=["scene", "spp", "entry", "metric", "value"])


def timings_frame() -> pd.DataFrame:
    rows = [(s, n, name, SECONDS[name]) for name in SECONDS if name != "noisy" for s, n in CASES]
    return pd.DataFrame(rows, columns=["scene", "spp", "method", "seconds"])


def test_comparison_role_of_each_kind_of_method():
    assert comparison_role(spec("oidn")) is None
    assert comparison_role(spec("deep_combiner", ["nfor"])) is None
    assert comparison_role(spec("ensemble", ["a", "b"])) is None
    assert comparison_role(spec("ensemble", ["a", "b"], seed=4, filter=True, solver="iterative")) is None
    assert comparison_role(spec("something_new", ["a"], weights="unconstrained")) is None
    assert comparison_role(spec("one_hot", ["a", "b"], prefilter="sbf")) == "one-hot sbf"
    assert comparison_role(spec("one_hot", ["a", "b"])) == "one-hot none"
    assert comparison_role(spec("naive_average", ["a", "b"])) == "naive average"
    assert comparison_role(spec("ensemble", ["a"], weights="unconstrained")) == "unconstrained weights"
    assert comparison_role(spec("ensemble", ["a"], solver="qp")) == "general QP solver"
    assert comparison_role(spec("ensemble", ["a"], solver="exact")) == "exact solver"
    assert comparison_role(spec("ensemble", ["a"], channels="single")) == "single-channel"
    assert comparison_role(spec("ensemble", ["a"], filter=False)) == "unfiltered"
    assert comparison_role(spec("ensemble", ["a"], filter=False, solver="qp")) == "ensemble variant"


def test_find_comparisons_matches_input_sets():
    found = find_comparisons(METHODS)
    assert list(found) == ["e2", "e3", "ebc"]
    assert found["e2"]["size"] == 2 and found["e3"]["size"] == 3
    assert found["e2"]["one_hot"] == {"sbf": "oh2_sbf", "nfor": "oh2_nfor", "post": "oh2_post"}
    assert found["e2"]["ablations"] == {"unconstrained weights": "e2_unc", "general QP solver": "e2_qp",
                                        "naive averaging": "avg2"}
    assert found["e3"]["one_hot"] == {"sbf": "oh3_sbf", "nfor": "oh3_nfor"}
    assert found["e3"]["ablations"] == {"single-channel": "e3_single", "unfiltered": "e3_raw"}
    assert found["ebc"]["one_hot"] == {} and found["ebc"]["ablations"] == {}


def test_two_methods_in_one_role_are_refused():
    methods = {**METHODS, "oh2_sbf_again": spec("one_hot", ["a", "b"], prefilter="sbf")}
    with pytest.raises(BenchError, match="'oh2_sbf' and 'oh2_sbf_again'.*one-hot sbf"):
        find_comparisons(methods)
    # roles no table uses may repeat
    variants = {f"v{i}": spec("ensemble", ["a", "b"], filter=False, solver=solver)
                for i, solver in enumerate(["qp", "exact"])}
    assert find_comparisons({**METHODS, **variants})["e2"] == find_comparisons(METHODS)["e2"]


def cell(table, size, spp):
    row = table[(table["size"] == str(size)) & (table["spp"] == str(spp))].iloc[0]
    return row["cases"], row["wins"], row["percent"]


def test_table1_against_hand_computed_percentages():
    cases, excluded = beats_cases(metrics_frame(), find_comparisons(METHODS), variants=("sbf", "nfor"))
    assert excluded == {"ebc": ["sbf", "nfor"]}
    table = beats_table(cases, sizes=[2, 3], spps=list(SPPS))
    # size 2: s1/4 win, s2/4 lose; s1/8 lose, s2/8 lose (a tie is no win)
    assert cell(table, 2, 4) == (2, 1, 50.0)
    assert cell(table, 2, 8) == (2, 0, 0.0)
    assert cell(table, 2, "Avg.") == (4, 1, 25.0)
    assert cell(table, 3, 4) == (2, 2, 100.0) and cell(table, 3, "Avg.") == (4, 4, 100.0)
    assert cell(table, "Avg.", 4) == (4, 3, 75.0)
    assert cell(table, "Avg.", 8) == (4, 2, 50.0)
    assert cell(table, "Avg.", "Avg.") == (8, 5, 62.5)


def test_table2_leaves_out_ensembles_without_the_post_variant_and_guards_empty_cells():
    cases, excluded = beats_cases(metrics_frame(), find_comparisons(METHODS), variants=("post",))
    assert excluded == {"e3": ["post"], "ebc": ["post"]}
    table = beats_table(cases, sizes=[2, 3], spps=list(SPPS))
    assert cell(table, 2, 4) == (2, 2, 100.0) and cell(table, 2, 8) == (2, 1, 50.0)
    n, wins, percent = cell(table, 3, "Avg.")
    assert (n, wins) == (0, 0) and pd.isna(percent)
    assert cell(table, "Avg.", "Avg.") == (4, 3, 75.0)


def test_a_missing_case_of_a_listed_method_stops_with_method_and_case_named():
    metrics = metrics_frame()
    lost = (metrics["entry"] == "oh2_nfor") & (metrics["scene"] == "s2") & (metrics["spp"] == 8)
    with pytest.raises(BenchError, match=r"m.csv: no relmse value for method 'oh2_nfor' in case scene s2, spp 8"):
        beats_cases(metrics[~lost], find_comparisons(METHODS), variants=("sbf", "nfor"), source="m.csv")
    # a method no table lists may be missing (the base denoiser c)
    beats_cases(metrics[metrics["entry"] != "c"], find_comparisons(METHODS), variants=("sbf", "nfor"))
    # a listed method that is missing everywhere, or a non-finite value, is refused as well
    with pytest.raises(BenchError, match="'oh2_post'"):
        beats_cases(metrics[metrics["entry"] != "oh2_post"], find_comparisons(METHODS), variants=("post",))
    broken = metrics.copy()
    broken.loc[(broken["entry"] == "e2") & (broken["metric"] == "relmse"), "value"] = float("nan")
    with pytest.raises(BenchError, match="method 'e2'.*not finite"):
        beats_cases(broken, find_comparisons(METHODS), variants=("post",))


def ablation_row(table, kind, spp):
    return table[(table["kind"] == kind) & (table["spp"] == str(spp))].iloc[0]


def test_ablation_table_against_hand_computed_means_and_rules():
    cases = ablation_cases(metrics_frame(), timings_frame(), find_comparisons(METHODS))
    table = ablation_table(cases, spps=list(SPPS))
    assert list(dict.fromkeys(table["kind"])) == ["unconstrained weights", "general QP solver", "single-channel",
                                                   "unfiltered", "naive averaging"]
    row = ablation_row(table, "unconstrained weights", 4)
    assert (row["cases"], row["relmse_ablation"], row["relmse_full"]) == (2, 2.0, 1.0)
    assert row["dssim_ablation"] == pytest.approx(0.2) and row["dssim_full"] == pytest.approx(0.1)
    assert row["loses"] == 1.0 and row["time_ratio"] == 1.0 and row["reproduced"] == "yes"
    qp = ablation_row(table, "general QP solver", "Avg.")
    assert qp["cases"] == 4 and qp["time_ratio"] == pytest.approx(10.0) and qp["reproduced"] == "yes"
    assert ablation_row(table, "single-channel", "Avg.")["reproduced"] == "no"
    raw = ablation_row(table, "unfiltered", "Avg.")     # 2, 0.5, 2, 0.5 against 1
    assert raw["relmse_ablation"] == pytest.approx(1.25) and raw["loses"] == 0.5 and raw["reproduced"] == "yes"
    raw8 = ablation_row(table, "unfiltered", 8)          # 0.5, 0.5: never loses
    assert raw8["loses"] == 0.0 and raw8["reproduced"] == "no"
    naive = ablation_row(table, "naive averaging", "Avg.")
    assert naive["section"] == "5.2.5" and naive["loses"] == 0.75 and naive["relmse_ablation"] == pytest.approx(2.375)
    assert naive["reproduced"] == "yes"


def test_ablation_table_without_dssim_and_a_missing_timing():
    cases = ablation_cases(metrics_frame(dssim=False), timings_frame(), find_comparisons(METHODS))
    table = ablation_table(cases, spps=list(SPPS))
    assert table["dssim_ablation"].isna().all() and table["relmse_full"].notna().all()
    timings = timings_frame()
    timings = timings[~((timings["method"] == "e2_qp") & (timings["scene"] == "s1") & (timings["spp"] == 4))]
    with pytest.raises(BenchError, match="t.csv: no seconds for method 'e2_qp' in case scene s1, spp 4"):
        ablation_cases(metrics_frame(), timings, find_comparisons(METHODS), timings_source="t.csv")


def brute_force_scores(values: dict[str, float]) -> dict[str, float]:
    """Best of K gets K, worst 1, ties the mean of their places."""
    others = list(values.values())
    return {name: 1 + sum(o > v for o in others) + 0.5 * (sum(o == v for o in others) - 1)
            for name, v in values.items()}


def test_comparison_ranking_holds_comparisons_their_ensembles_and_noisy():
    table = comparison_ranking(metrics_frame(), METHODS, "relmse")
    expected = {"e2", "e3", "oh2_sbf", "oh2_nfor", "oh2_post", "oh3_sbf", "oh3_nfor", "avg2", "e2_unc", "e2_qp",
                "e3_single", "e3_raw", "noisy"}
    assert set(table.index) == expected            # not the base denoisers, not ebc (no comparison)
    for spp in SPPS:
        per_scene = [brute_force_scores({n: RELMSE[n][CASES.index((s, spp))] for n in expected}) for s in SCENES]
        for name in expected:
            assert table.loc[name, str(spp)] == pytest.approx(sum(p[name] for p in per_scene) / len(SCENES))
    assert table.loc["oh2_sbf", "role"] == "one-hot sbf" and table.loc["oh2_sbf", "compared_with"] == "e2"
    assert table.loc["e3", "role"] == "full ensemble" and table.loc["e3_raw", "compared_with"] == "e3"
    assert comparison_ranking(metrics_frame(), {n: METHODS[n] for n in ("a", "e2")}, "relmse").empty


def write_inputs(tmp_path):
    metrics_csv, timings_csv = tmp_path / "metrics.csv", tmp_path / "timings.csv"
    metrics_frame().to_csv(metrics_csv, index=False)
    timings_frame().to_csv(timings_csv, index=False)
    return str(metrics_csv), str(timings_csv)


def test_write_steps_write_csv_and_markdown(tmp_path):
    metrics_csv, timings_csv = write_inputs(tmp_path)
    labels = {name: s["label"] for name, s in METHODS.items()}
    out = {k: str(tmp_path / f"{k}") for k in ("t1.csv", "t1.md", "t2.csv", "t2.md", "a.csv", "a.md", "r.csv", "r.md")}
    write_onehot_tables(metrics_csv, "relmse", methods=METHODS, labels=labels, table1_csv=out["t1.csv"],
                        table1_md=out["t1.md"], table2_csv=out["t2.csv"], table2_md=out["t2.md"])
    table1 = pd.read_csv(out["t1.csv"], dtype={"size": str, "spp": str})
    assert cell(table1, "Avg.", "Avg.") == (8, 5, 62.5)
    text = Path(out["t1.md"]).read_text()
    assert "| 2 | 50.0 % (2) | 0.0 % (2) | 25.0 % (4) |" in text
    assert "| Zheng et al. | 85.1 % | 80.8 % | 74.9 % |" in text and "| ours | 75.0 % | 50.0 % | 62.5 % |" in text
    assert "Not in this table (variant set incomplete): " + labels["ebc"] in text
    assert "| 3 | – (0) | – (0) | – (0) |" in Path(out["t2.md"]).read_text()
    write_ablation_table(metrics_csv, timings_csv, methods=METHODS, labels=labels, csv_path=out["a.csv"],
                         md_path=out["a.md"])
    assert "| general QP solver (5.2.2) | Avg. | 4 |" in Path(out["a.md"]).read_text()
    write_comparison_ranking(metrics_csv, "dssim", methods=METHODS, labels=labels, csv_path=out["r.csv"],
                             md_path=out["r.md"])
    assert set(pd.read_csv(out["r.csv"])["candidate"]) >= {"e2", "avg2", "noisy"}
    assert all("nan" not in Path(p).read_text().lower() for p in out.values())


@pytest.fixture
def job_threads_restored(monkeypatch):
    """The rule script holds this process's thread pools to its job's threads
    (:func:`mcbench.pipeline.threads.limit_threads`): put the environment and numba's pool back."""
    import os

    import numba

    from mcbench.pipeline.threads import THREAD_COUNT_VARIABLES, WAIT_VARIABLES

    for name in (*THREAD_COUNT_VARIABLES, *WAIT_VARIABLES):
        if name in os.environ:
            monkeypatch.setenv(name, os.environ[name])
        else:
            monkeypatch.delenv(name, raising=False)
    threads = numba.get_num_threads()
    yield
    numba.set_num_threads(threads)


def test_rule_scripts_run_each_step_without_snakemake(tmp_path, job_threads_restored):
    """Each comparison rule's script (workflow/scripts/<rule>.py) runs its step on a stand-in
    ``snakemake`` object."""
    metrics_csv, timings_csv = write_inputs(tmp_path)
    labels = {name: s["label"] for name, s in METHODS.items()}
    params = SimpleNamespace(methods=METHODS, labels=labels)
    fake = SimpleNamespace(input=SimpleNamespace(metrics=metrics_csv, timings=timings_csv),
                           output=SimpleNamespace(csv=str(tmp_path / "a.csv"), md=str(tmp_path / "a.md")),
                           params=params, wildcards=SimpleNamespace(), log=[str(tmp_path / "a.log")], threads=1)
    runpy.run_path(str(ROOT / "workflow/scripts/comparison_ablations.py"), init_globals={"snakemake": fake})
    assert "naive averaging (5.2.5)" in (tmp_path / "a.md").read_text()
    fake.wildcards = SimpleNamespace(metric="relmse")
    fake.output = SimpleNamespace(csv=str(tmp_path / "r.csv"), md=str(tmp_path / "r.md"))
    runpy.run_path(str(ROOT / "workflow/scripts/comparison_ranking.py"), init_globals={"snakemake": fake})
    assert "[one-hot post]" in (tmp_path / "r.md").read_text()
    fake.output = SimpleNamespace(**{f"table{k}_{ext}": str(tmp_path / f"t{k}.{ext}") for k in (1, 2) for ext in ("csv", "md")})
    runpy.run_path(str(ROOT / "workflow/scripts/comparison_onehot.py"), init_globals={"snakemake": fake})
    assert (tmp_path / "t1.md").read_text() and (tmp_path / "t2.csv").read_text()


def test_ensemble_defaults_are_the_ensembles_own():
    """The comparisons read the ensemble's defaults from their one owner in mcbench.combine, and
    the ensemble plugin's combine() takes them as its defaults."""
    import inspect

    from mcbench.analysis import comparison_tables
    from mcbench.combine.ensemble_weights import ENSEMBLE_DEFAULTS
    from methods import load_method

    assert comparison_tables.ENSEMBLE_DEFAULTS is ENSEMBLE_DEFAULTS
    signature = inspect.signature(load_method("ensemble").combine)
    assert {key: signature.parameters[key].default for key in ENSEMBLE_DEFAULTS} == ENSEMBLE_DEFAULTS
