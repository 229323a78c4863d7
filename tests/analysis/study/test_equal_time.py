"""mcbench.analysis.study.equal_time against closed-form equal-time power laws and render records
written to disk."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from mcbench.analysis.study.equal_time import equal_time_curves, equal_time_table, loglog_interp, read_render_seconds
from tests.analysis.study.synthetic_timings import (SCENES, SPPS, METHODS, INPUTS, RENDER_SECONDS_PER_SPP,
                                                    NOISY_CONSTANT, synthetic_study, render_times, write_records)


# ----------------------------------------------------------------------------- equal time


def test_loglog_interp_is_exact_on_power_laws_inside_and_beyond():
    xp = np.array([4.0, 8.0, 16.0, 32.0])
    values, beyond = loglog_interp([4.0, 6.0, 20.0, 100.0, 2.0], xp, 3.0 * xp ** -1.5)
    assert np.allclose(values, 3.0 * np.array([4.0, 6.0, 20.0, 100.0, 2.0]) ** -1.5)
    assert beyond.tolist() == [False, False, False, True, True]
    single, _ = loglog_interp(20.0, [10.0], [5.0])  # one point: proportional
    assert single[0] == pytest.approx(10.0)


def test_equal_time_on_synthetic_power_laws():
    """time = a spp, noisy error = c / spp: a candidate costing m seconds at spp has the equal-time
    spp spp + m / a and the noisy error there c / (spp + m / a), in range or beyond it."""
    metrics, timings = synthetic_study()
    table = equal_time_table(metrics, timings, render_times(), metric="relmse", inputs=INPUTS)
    assert len(table) == len(SCENES) * len(SPPS) * len(METHODS)
    totals = {"kpcn": 2.0, "nfor": 3.0, "rdfc": 0.5, "kpcn_dc": 3.0, "ens10": 5.25, "ens18": 5.625}
    relmse = metrics[metrics.metric == "relmse"].set_index(["scene", "spp", "entry"])["value"]
    for row in table.itertuples():
        cost = totals[row.candidate]
        equal_spp = row.spp + cost / RENDER_SECONDS_PER_SPP
        assert row.method_seconds == pytest.approx(cost)
        assert row.render_seconds == pytest.approx(RENDER_SECONDS_PER_SPP * row.spp)
        assert row.equal_spp == pytest.approx(equal_spp)
        assert row.noisy_error == pytest.approx(NOISY_CONSTANT / equal_spp)
        assert row.ratio == pytest.approx(relmse[(row.scene, row.spp, row.candidate)] * equal_spp / NOISY_CONSTANT)
        assert row.extrapolated == (equal_spp > max(SPPS))
    assert table["extrapolated"].any() and not table["extrapolated"].all()
    numeric = table.drop(columns=["scene", "candidate", "extrapolated"]).to_numpy(np.float64)
    assert np.isfinite(numeric).all()

    ratios, beyond = equal_time_curves(table, candidates=["kpcn", "ens18"])
    for spp, name in itertools.product(SPPS, ["kpcn", "ens18"]):
        per_scene = table[(table.spp == spp) & (table.candidate == name)]["ratio"]
        assert ratios.loc[spp, name] == pytest.approx(float(np.exp(np.log(per_scene).mean())))
    assert beyond.dtypes.eq(bool).all() and not ratios.isna().any().any()


def test_equal_time_ignores_a_render_time_that_falls():
    metrics, timings = synthetic_study()
    times = render_times()
    slow = (times.scene == "box") & (times.spp == 8)
    times.loc[slow, "seconds"] = 10.0  # timing noise: 8 spp slower than 16 and 32
    table = equal_time_table(metrics, timings, times, metric="relmse", inputs=INPUTS, candidates=["rdfc"])
    box = table[table.scene == "box"].set_index("spp")
    assert box.loc[16, "render_seconds"] == pytest.approx(10.0)  # raised to the running maximum
    assert (box["equal_spp"] >= box.index.to_numpy()).all()
    assert np.isfinite(table["ratio"]).all()


def test_equal_time_names_a_missing_render_time():
    metrics, timings = synthetic_study()
    times = render_times()
    times = times[~((times.scene == "glass_room") & (times.spp == 16))]
    with pytest.raises(ValueError, match="no render time for scene 'glass_room' at 16 spp"):
        equal_time_table(metrics, timings, times, metric="relmse", inputs=INPUTS)


def test_read_render_seconds_prefers_the_exr_header(tmp_path):
    frame = read_render_seconds(write_records(tmp_path))
    assert len(frame) == len(SCENES) * len(SPPS)
    box4 = frame[(frame.scene == "box") & (frame.spp == 4)].iloc[0]
    assert box4["seconds"] == pytest.approx(0.1) and box4["source"] == "exr"
    glass = frame[(frame.scene == "glass_room") & (frame.spp == 32)].iloc[0]
    assert glass["seconds"] == pytest.approx(RENDER_SECONDS_PER_SPP * 32) and glass["source"] == "benchmark"
    with pytest.raises(ValueError, match="neither a render"):
        read_render_seconds([str(tmp_path / "x.txt")])


def test_equal_time_refuses_a_render_time_that_is_not_positive():
    metrics, timings = synthetic_study()
    times = render_times()
    times.loc[0, "seconds"] = 0.0
    with pytest.raises(ValueError, match="must be positive"):
        equal_time_table(metrics, timings, times, metric="relmse", inputs=INPUTS)
