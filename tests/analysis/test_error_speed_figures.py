"""mcbench.analysis.error_speed_figures: the report's error curves and speed-against-error figure, checked against
means computed by hand on synthetic tables, and the PNGs they write."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from mcbench.analysis.error_speed_figures import (MEAN_PANEL, combined_seconds, error_curves, error_curves_figure,
                                                  speed_error_figure, speed_error_points)

SCENES = ["box", "glass"]
SPPS = [4, 16, 64]
CANDIDATES = ["noisy", "oidn", "jbf", "ens"]


def synthetic_metrics(seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = [{"scene": scene, "spp": spp, "entry": entry, "metric": metric,
             "value": float(rng.uniform(0.001, 1.0))}
            for scene, spp, entry, metric in itertools.product(SCENES, SPPS, CANDIDATES, ["relmse", "dssim"])]
    return pd.DataFrame(rows).sample(frac=1.0, random_state=seed)  # row order must not matter


def synthetic_timings(seed: int = 1) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = [{"scene": scene, "spp": spp, "method": method, "seconds": float(rng.uniform(0.1, 5.0))}
            for scene, spp, method in itertools.product(SCENES, SPPS, ["oidn", "jbf", "ens"])]
    return pd.DataFrame(rows)


def test_error_curves_are_the_table_and_its_mean_over_scenes():
    metrics = synthetic_metrics()
    panels = error_curves(metrics, metric="dssim")
    assert list(panels)[0] == MEAN_PANEL and set(panels) == {MEAN_PANEL, *SCENES}
    for scene, spp, candidate in itertools.product(SCENES, SPPS, CANDIDATES):
        row = metrics[(metrics.scene == scene) & (metrics.spp == spp) & (metrics.entry == candidate)
                      & (metrics.metric == "dssim")]
        assert panels[scene].loc[spp, candidate] == row["value"].item()
    for spp, candidate in itertools.product(SPPS, CANDIDATES):
        by_hand = np.mean([panels[scene].loc[spp, candidate] for scene in SCENES])
        assert panels[MEAN_PANEL].loc[spp, candidate] == pytest.approx(by_hand, rel=1e-12)
    assert list(panels["box"].index) == SPPS  # ascending spp whatever the row order


def test_error_curves_name_a_missing_metric():
    with pytest.raises(ValueError, match="no 'flip' values.*dssim, relmse"):
        error_curves(synthetic_metrics(), metric="flip")


def test_combined_seconds_add_the_inputs_of_combiners_recursively_each_once():
    own = {"a": 1.0, "b": 2.5, "ens": 0.5, "ens_of_ens": 0.25}
    inputs = {"ens": ["a", "b"], "ens_of_ens": ["ens", "a"]}
    totals = combined_seconds(own, inputs)
    # a is reached twice by ens_of_ens but runs once per case
    assert totals == {"a": 1.0, "b": 2.5, "ens": 4.0, "ens_of_ens": 0.25 + 0.5 + 1.0 + 2.5}
    with pytest.raises(ValueError, match="no timing for method 'c'"):
        combined_seconds({"ens": 1.0}, {"ens": ["c"]})
    with pytest.raises(ValueError, match="takes itself"):
        combined_seconds({"x": 1.0, "y": 1.0}, {"x": ["y"], "y": ["x"]})


def test_speed_error_points_are_means_over_cases():
    metrics, timings = synthetic_metrics(), synthetic_timings()
    points = speed_error_points(metrics, timings, metric="relmse", inputs={"ens": ["oidn", "jbf"]})
    assert list(points.index) == ["oidn", "jbf", "ens"]  # no row for the noisy input
    for method in points.index:
        seconds = timings[timings.method == method]["seconds"]
        errors = metrics[(metrics.entry == method) & (metrics.metric == "relmse")]["value"]
        assert points.loc[method, "seconds"] == pytest.approx(seconds.sum() / len(seconds), rel=1e-12)
        assert points.loc[method, "error"] == pytest.approx(errors.sum() / len(errors), rel=1e-12)
        assert points.loc[method, "runs"] == len(SCENES) * len(SPPS)
    assert points.loc["ens", "total_seconds"] == pytest.approx(points["seconds"].sum(), rel=1e-12)
    assert points.loc["jbf", "total_seconds"] == points.loc["jbf", "seconds"]
    with pytest.raises(ValueError, match="timed method.*ens"):
        speed_error_points(metrics[metrics.entry != "ens"], timings, metric="relmse")


def _png_pixels(path):
    import matplotlib.image

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return matplotlib.image.imread(path)


def test_figures_write_pngs_with_content(tmp_path):
    metrics = synthetic_metrics()
    metrics.loc[metrics.index[0], "value"] = 0.0  # not drawable on a log axis: a gap, no failure
    labels = {"noisy": "Noisy input", "oidn": "OIDN", "jbf": "JBF", "ens": "Ensemble"}
    curves = tmp_path / "figures" / "error_relmse.png"
    error_curves_figure(error_curves(metrics, metric="relmse"), curves, metric="relmse", labels=labels)
    speed = tmp_path / "speed.png"
    points = speed_error_points(metrics, synthetic_timings(), metric="relmse", inputs={"ens": ["oidn", "jbf"]})
    speed_error_figure(points, speed, metric="relmse", labels=labels)
    for path in (curves, speed):
        pixels = _png_pixels(path)
        assert pixels.shape[0] > 200 and pixels.shape[1] > 300
        assert np.std(pixels[..., :3]) > 0.05  # drawn, not blank
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["error_relmse.png", "figures", "speed.png"]  # no temp left
