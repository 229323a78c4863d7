"""tools/isa_reproducibility.py's comparison on constructed results folders whose differences are
known: identical trees are identical, a one-ulp change in one method output or one metric value
is found (and only there), a moved score is placed against its bootstrap interval."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mcbench.io.exr import write_layers

TOOL = Path(__file__).resolve().parents[2] / "tools" / "isa_reproducibility.py"


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("isa_reproducibility", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module                 # its dataclass looks its module up
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def _results(root, *, pixel=0.3, metric=0.125, avg=4.5):
    """A results folder: two method outputs, metrics.csv, a ranking table and a study interval table."""
    color = np.full((4, 4, 3), 0.3, np.float32)
    color[1, 2, 0] = pixel
    write_layers(root / "outputs" / "s" / "spp4" / "oidn.exr", {"color": color})
    write_layers(root / "outputs" / "s" / "spp4" / "jbf.exr", {"color": np.full((4, 4, 3), 0.5, np.float32)})
    pd.DataFrame({"scene": ["s"] * 4, "spp": [4] * 4, "entry": ["oidn", "oidn", "jbf", "jbf"],
                  "metric": ["relmse", "dssim"] * 2, "value": [metric, 0.25, 0.5, 0.75]}).to_csv(
        root / "metrics.csv", index=False)
    (root / "tables" / "study").mkdir(parents=True)
    pd.DataFrame({"candidate": ["jbf", "oidn"], "4": [3.0, avg], "Avg.": [3.0, avg]}).to_csv(
        root / "tables" / "ranking_relmse.csv", index=False)
    pd.DataFrame({"candidate": ["jbf", "oidn"], "avg": [3.0, avg], "avg_ci_low": [2.0, 3.5], "avg_ci_high": [4.0, 5.0],
                  **{f"{c}{s}": [np.nan, np.nan] for c in ("low", "medium", "high") for s in ("", "_ci_low", "_ci_high")}}
                 ).to_csv(root / "tables" / "study" / "scores_ci_relmse.csv", index=False)
    return root


def test_identical_trees_are_identical(tool, tmp_path):
    a, b = _results(tmp_path / "a"), _results(tmp_path / "b")
    stage, found = tool.image_stage(a, b, "outputs")
    assert (stage.files, stage.differing, found) == (2, 0, [])
    assert tool.metrics_differences(a, b)["differing"].sum() == 0
    assert tool.ranking_moves(a, b).empty and tool.interval_moves(a, b).empty


def test_one_ulp_in_one_output_and_one_metric_differs_there_alone(tool, tmp_path):
    ulp_pixel = float(np.nextafter(np.float32(0.3), np.float32(1)))
    ulp_metric = float(np.nextafter(0.125, 1.0))
    a, b = _results(tmp_path / "a"), _results(tmp_path / "b", pixel=ulp_pixel, metric=ulp_metric)
    stage, found = tool.image_stage(a, b, "outputs")
    assert stage.differing == 1 and [d.table for d in found] == [str(Path("outputs/s/spp4/oidn.exr"))]
    methods = tool.per_method(found, a, b)
    assert list(methods["method"]) == ["oidn"]
    assert methods["max_abs"].iloc[0] == pytest.approx(ulp_pixel - float(np.float32(0.3)), rel=1e-9)
    assert methods["color_max_abs"].iloc[0] == methods["max_abs"].iloc[0]
    metrics = tool.metrics_differences(a, b).set_index(["entry", "metric"])
    assert metrics["differing"].to_dict() == {("jbf", "dssim"): 0, ("jbf", "relmse"): 0,
                                              ("oidn", "dssim"): 0, ("oidn", "relmse"): 1}
    assert metrics.at[("oidn", "relmse"), "max_rel"] == pytest.approx((ulp_metric - 0.125) / ulp_metric, rel=1e-9)


@pytest.mark.parametrize("moved, inside", [(4.75, True), (5.25, False), (2.5, False)])
def test_a_moved_score_is_placed_against_the_first_runs_interval(tool, tmp_path, moved, inside):
    a, b = _results(tmp_path / "a"), _results(tmp_path / "b", avg=moved)
    moves = tool.interval_moves(a, b)
    assert moves[["candidate", "score", "b", "inside"]].values.tolist() == [["oidn", "avg", moved, inside]]
    ranking = tool.ranking_moves(a, b)
    changed_place = moved < 3.0                     # below jbf's 3.0: oidn falls from first to second
    assert ("place (Avg.)" in set(ranking["column"])) == changed_place
    assert set(ranking.loc[ranking["column"] != "place (Avg.)", "column"]) == {"4", "Avg."}
