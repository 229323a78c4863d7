"""mcbench.analysis.study.study_figures: the PNGs of a tiny synthetic study, the figure set and the curves
drawn."""

from __future__ import annotations


import numpy as np
import pandas as pd
import pytest

from mcbench.analysis.study.study_figures import (STUDY_FIGURES, curve_candidates, paper_recommended,
                                                  study_figure_paths, write_study_figures)
from tests.analysis.study.synthetic_timings import SCENES, SPPS, METHODS, INPUTS, synthetic_study, write_records


# ----------------------------------------------------------------------------- figures


def test_write_study_figures_writes_every_png(tmp_path):
    metrics, timings = synthetic_study()
    metrics_csv, timings_csv = tmp_path / "metrics.csv", tmp_path / "timings.csv"
    metrics.to_csv(metrics_csv, index=False)
    timings.to_csv(timings_csv, index=False)
    paths = study_figure_paths(tmp_path / "figures" / "study", "relmse")
    assert list(paths) == list(STUDY_FIGURES)
    assert all(p.endswith(f"{key}_relmse.png") for key, p in paths.items())
    ci = pd.DataFrame({"candidate": METHODS, "ci_low": [1.0] * 6, "ci_high": [7.0] * 6})
    table = write_study_figures(str(metrics_csv), str(timings_csv), write_records(tmp_path), paths, metric="relmse",
                                candidates=METHODS, curves=["kpcn", "nfor", "rdfc", "ens10", "ens18"],
                                recommended=["ens18"], labels={"noisy": "Noisy", "kpcn": "KPCN"}, inputs=INPUTS,
                                ci=ci)
    for path in paths.values():
        with open(path, "rb") as handle:
            assert handle.read(8) == b"\x89PNG\r\n\x1a\n"
    assert len(table) == len(SCENES) * len(SPPS) * len(METHODS)
    assert np.isfinite(table.drop(columns=["scene", "candidate", "extrapolated"]).to_numpy(np.float64)).all()


def test_write_study_figures_refuses_an_unknown_figure(tmp_path):
    with pytest.raises(ValueError, match="unknown study figure"):
        write_study_figures("m.csv", "t.csv", [], {"pie": str(tmp_path / "pie.png")}, metric="relmse",
                            candidates=METHODS, curves=METHODS)


def test_paper_recommended_and_curve_candidates():
    assert paper_recommended() == ["ens27", "ens20", "ens10", "ens18"]
    assert curve_candidates(["ens20", "kpcn", "ens20"]) == ["kpcn", "nfor_dc", "mcgan", "nfor", "kpcn_dc", "oidn",
                                                           "optix_ae", "rdfc", "ens20"]
