"""Progressive denoising's tables (mcbench.analysis.progressive_tables) on constructed metrics whose
counts, ratios and gaps are known by construction."""

import numpy as np
import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.analysis.progressive_tables import (added_seconds, consistency_summary, consistency_table, geometric_ratio,
                                        per_spp_table, table_entries)

SPPS = [4, 16, 64, 256]
SCENES = ["a", "b", "c"]


def _metrics(values: dict[str, dict[tuple[str, int], float]], metric: str = "relmse") -> pd.DataFrame:
    rows = [{"scene": scene, "spp": spp, "entry": name, "metric": metric, "value": value}
            for name, cases in values.items() for (scene, spp), value in cases.items()]
    return pd.DataFrame(rows)


def _constructed():
    """noisy ~ 1/spp; PD = noisy * r(spp) with r rising to 1 (scene c at 4 spp: 1.5, an exception);
    the base: a bias floor 0.01 (1 + i) that overtakes the noisy error at high spp."""
    ratio = {4: 0.2, 16: 0.4, 64: 0.7, 256: 0.95}
    noisy, pd_, base = {}, {}, {}
    for i, scene in enumerate(SCENES):
        for spp in SPPS:
            x = (1.0 + i) / spp
            noisy[(scene, spp)] = x
            pd_[(scene, spp)] = x * (1.5 if (scene, spp) == ("c", 4) else ratio[spp])
            base[(scene, spp)] = 0.01 * (1 + i) + 0.05 * x
    return _metrics({"noisy": noisy, "pd_oidn": pd_, "oidn": base}), ratio


def test_consistency_counts_ratios_and_gaps_by_construction():
    metrics, ratio = _constructed()
    table = consistency_table(metrics, {"pd_oidn": "oidn"})
    assert list(table["spp"]) == SPPS and set(table["entry"]) == {"pd_oidn"}
    assert list(table["worse"]) == [1, 0, 0, 0]
    assert list(table["cases"]) == [3, 3, 3, 3]
    # geometric mean of the per-scene ratios
    expected4 = (0.2 * 0.2 * 1.5) ** (1 / 3)
    assert table["ratio"].iloc[0] == pytest.approx(expected4)
    for spp, value in zip(SPPS[1:], table["ratio"].iloc[1:]):
        assert value == pytest.approx(ratio[spp])
    # gap: mean |z - x| = mean over scenes of x * |r - 1|
    x16 = np.array([1, 2, 3]) / 16
    assert table["gap"].iloc[1] == pytest.approx(np.mean(x16 * 0.6))
    # the base's floor 0.01 (1 + i) beats noisy at 4 spp, not at 256 spp: (1 + i)/256 < 0.01 (1 + i)
    assert table["input_worse"].iloc[0] == 0 and table["input_worse"].iloc[-1] == 3
    assert table["input_ratio"].iloc[-1] > 1 > table["ratio"].iloc[-1]

    summary = consistency_summary(table)
    row = summary.iloc[0]
    assert row["worse"] == 1 and row["cases"] == 12 and row["input_worse"] >= 3
    assert row["gap_shrinks"] and row["gap_monotone"]
    assert row["gap_last"] < row["gap_first"]


def test_gap_not_monotone_is_reported():
    metrics, _ = _constructed()
    # make PD at 64 spp 4x the noisy error (gap 3 x = 3 * 2/64 on average), above the 16-spp gap 0.6 * 2/16
    mask = (metrics["entry"] == "pd_oidn") & (metrics["spp"] == 64)
    metrics.loc[mask, "value"] = metrics.loc[mask, "value"] * (4.0 / 0.7)
    table = consistency_table(metrics, {"pd_oidn": "oidn"})
    gaps = table["gap"].to_numpy()
    assert gaps[2] > gaps[1]
    summary = consistency_summary(table).iloc[0]
    assert not summary["gap_monotone"] and summary["gap_shrinks"]


def test_geometric_ratio_guards_zero():
    assert geometric_ratio(np.array([0.0, 2.0]), np.array([0.0, 1.0])) == pytest.approx(np.sqrt(2.0))
    value = geometric_ratio(np.array([1e-3]), np.array([0.0]))
    assert np.isfinite(value) and value > 1


def test_missing_candidate_names_it():
    metrics, _ = _constructed()
    with pytest.raises(BenchError, match="pd_kpcn"):
        consistency_table(metrics, {"pd_kpcn": "kpcn"})
    with pytest.raises(BenchError, match="smape"):
        per_spp_table(metrics, ["noisy"], metric="smape")


def test_per_spp_means_and_seconds():
    metrics, _ = _constructed()
    entries = table_entries({"pd_oidn": "oidn", "pd_oidn_no_ttest": "oidn"})
    assert entries == ["noisy", "oidn", "pd_oidn", "pd_oidn_no_ttest"]
    table = per_spp_table(metrics, ["noisy", "pd_oidn"], metric="relmse")
    assert table.loc["noisy", "4"] == pytest.approx(np.mean([1, 2, 3]) / 4)
    assert table.loc["noisy", "avg"] == pytest.approx(np.mean([2 / s for s in SPPS]))
    timings = pd.DataFrame([{"scene": s, "spp": spp, "method": m, "seconds": t}
                            for s in SCENES for spp in SPPS for m, t in (("pd_oidn", 0.3), ("oidn", 0.1))])
    seconds = added_seconds(timings, ["noisy", "oidn", "pd_oidn"])
    assert list(seconds.index) == ["oidn", "pd_oidn"]
    assert seconds.loc["pd_oidn", "avg"] == pytest.approx(0.3)
