"""Fast tests of the rule bodies in ``mcbench.pipeline`` on tiny synthetic EXRs: each step's files
against the project functions (or closed forms) recomputed here from the same inputs."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from mcbench import NOISY, BenchError

from mcbench.pipeline import evaluation, method_runs, rankings, rendering
from mcbench.pipeline.cases import run_case
from mcbench.pipeline.registry import load_metric
from mcbench.io.buffers import Denoised, RenderBuffers, stored_layers
from mcbench.io.exr import read_layers, read_metadata, write_layers
from methods import load_method
from tests.conftest import case_job

#: The metrics of the case tables below (the reference has no variance: no relmse_corrected).
METRICS = ["relmse", "smape", "dssim", "flip"]

SCENE, SPP = "box", 8


@pytest.fixture
def case_files(tmp_path, make_render_buffers):
    """A render EXR and its noise-free reference EXR (16 x 16)."""
    buffers = make_render_buffers(spp=SPP, half_std=0.05, seed=7)
    truth = make_render_buffers(spp=SPP, half_std=0.0).color
    render, reference = tmp_path / "render.exr", tmp_path / "reference.exr"
    write_layers(render, buffers.layers, metadata={"spp": SPP, "scene": SCENE})
    write_layers(reference, {"color": truth}, metadata={"spp": 4096, "scene": SCENE})
    return render, reference


def run(method, render, tmp_path, **kw):
    output, timing = tmp_path / f"{method}.exr", tmp_path / f"{method}.json"
    method_runs.run_method(method, str(render), str(output), str(timing), scene=SCENE, spp=SPP,
                     threads=1, **kw)
    return output, timing


@pytest.mark.parametrize("name", ["jbf", "oidn"])
def test_run_method_writes_the_methods_output_and_its_timing(name, case_files, tmp_path):
    render, _ = case_files
    output, timing = run(f"{name}_run", render, tmp_path, module_name=name)
    expected = load_method(name).denoise(RenderBuffers.load(render))
    written = Denoised.load(output)
    for which in ("full", "a", "b"):
        np.testing.assert_array_equal(getattr(written, which), getattr(expected, which))
    meta = read_metadata(output)
    assert (meta["method"], meta["scene"], meta["spp"]) == (f"{name}_run", SCENE, str(SPP))
    record = json.loads(timing.read_text())
    assert {k: record[k] for k in ("scene", "spp", "method", "module", "kind", "width", "height",
                                   "threads")} == {
        "scene": SCENE, "spp": SPP, "method": f"{name}_run", "module": name, "kind": "denoiser",
        "width": 16, "height": 16, "threads": 1}
    assert 0.0 < record["seconds"] < 60.0
    assert float(meta["seconds"]) == pytest.approx(record["seconds"], abs=1e-6)


def test_run_method_combiner_reads_its_inputs(case_files, tmp_path):
    render, _ = case_files
    inputs = [run(name, render, tmp_path, module_name=name)[0] for name in ("jbf", "oidn")]
    output, timing = run("ens", render, tmp_path, module_name="ensemble",
                         params={"solver": "exact"}, input_paths=[str(p) for p in inputs])
    expected = load_method("ensemble").combine(RenderBuffers.load(render),
                                               [Denoised.load(p) for p in inputs], solver="exact")
    layers = read_layers(output)
    # the file keeps what later steps read (mcbench.io.buffers.stored_layers), bit for bit
    for name, value in stored_layers(expected).items():
        np.testing.assert_array_equal(layers[name], value.astype(np.float32))
    assert set(layers) == set(stored_layers(expected)) and "weights_raw_0" not in layers
    assert layers["weights_filtered_0"].ndim == 2
    assert json.loads(timing.read_text())["kind"] == "combiner"


def test_run_methods_in_one_job_equals_one_job_per_method(case_files, tmp_path):
    """A batch (base denoisers, a combiner of them, a combiner of that combiner) writes exactly the
    files that one run_method per method writes, in dependency order within the call."""
    render, _ = case_files
    specs = [("jbf", "jbf", {}, []), ("oidn", "oidn", {}, []),
             ("ens", "ensemble", {"solver": "exact"}, ["jbf", "oidn"]),
             ("avg", "naive_average", {}, ["ens", "oidn"])]
    single, batch = tmp_path / "single", tmp_path / "batch"
    single.mkdir(), batch.mkdir()
    for name, module, params, inputs in specs:
        method_runs.run_method(name, str(render), str(single / f"{name}.exr"), str(single / f"{name}.json"),
                         module_name=module, params=params,
                         input_paths=[str(single / f"{i}.exr") for i in inputs], scene=SCENE, spp=SPP)
    method_runs.run_methods([{"name": name, "module": module, "params": params,
                        "input_paths": [str(batch / f"{i}.exr") for i in inputs],
                        "exr": str(batch / f"{name}.exr"), "timing": str(batch / f"{name}.json")}
                       for name, module, params, inputs in specs], str(render), scene=SCENE, spp=SPP)
    for name, *_ in specs:
        one, other = read_layers(single / f"{name}.exr"), read_layers(batch / f"{name}.exr")
        assert one.keys() == other.keys()
        for layer in one:
            np.testing.assert_array_equal(one[layer], other[layer])
        assert json.loads((batch / f"{name}.json").read_text())["method"] == name


def test_run_methods_names_a_missing_input(case_files, tmp_path):
    render, _ = case_files
    with pytest.raises(Exception, match="missing.exr"):
        method_runs.run_methods([{"name": "ens", "module": "ensemble", "params": {},
                            "input_paths": [str(tmp_path / "missing.exr")],
                            "exr": str(tmp_path / "ens.exr"), "timing": str(tmp_path / "ens.json")}],
                          str(render))


def test_run_method_refuses_an_input_of_another_size(case_files, tmp_path, make_render_buffers):
    render, _ = case_files
    small = make_render_buffers(height=8, width=8)
    wrong = tmp_path / "wrong.exr"
    write_layers(wrong, {"color": small.color, "color_a": small.color_a, "color_b": small.color_b})
    with pytest.raises(BenchError, match="wrong.exr.*does not match"):
        run("ens", render, tmp_path, module_name="ensemble", input_paths=[str(wrong)])


def case_metrics(render, reference, tmp_path, *, scene=SCENE, spp=SPP, metric_names=METRICS):
    """The case job (rule run_case's code) with one method, jbf: its metrics table, the table's
    path and jbf's output."""
    folder = tmp_path / f"case_{scene}_{spp}"
    run_case(case_job(folder, scene=scene, spp=spp, render=render, reference=reference, metrics=metric_names,
                      methods=[("jbf", "jbf", {}, [])]))
    csv = folder / "case.csv"
    return pd.read_csv(csv), csv, folder / "outputs" / "jbf.exr"


def test_the_case_table_equals_the_metrics_recomputed(case_files, tmp_path):
    render, reference = case_files
    frame, csv, output = case_metrics(render, reference, tmp_path)
    truth = read_layers(reference, ["color"])["color"]
    images = {NOISY: RenderBuffers.load(render).color, "jbf": Denoised.load(output).full}
    assert list(frame.columns) == ["scene", "spp", "entry", "metric", "value"]
    assert list(zip(frame.entry, frame.metric)) == [(entry, m) for entry in images for m in METRICS]
    for row in frame.itertuples():
        assert (row.scene, row.spp) == (SCENE, SPP)
        assert row.value == load_metric(row.metric).value(images[row.entry], truth)
    assert frame.set_index(["entry", "metric"]).loc[("jbf", "relmse"), "value"] < \
        frame.set_index(["entry", "metric"]).loc[(NOISY, "relmse"), "value"]


def test_the_case_job_draws_the_flip_map_its_flip_value_comes_from(case_files, tmp_path):
    """One FLIP evaluation per entry: the viewer's FLIP map is HDR-FLIP's per-pixel map, on the
    FLIP scale, and the table's flip value is the package's mean of it; the relMSE map is drawn
    too, and no other metric has a map."""
    from mcbench.analysis.metrics import flip, flip_map, relmse_map
    from mcbench.analysis.viewer_images import FLIP_SCALE, RELMSE_SCALE, scale_indices, write_indexed_png

    render, reference = case_files
    frame, csv, output = case_metrics(render, reference, tmp_path, metric_names=["relmse", "smape", "flip"])
    truth = read_layers(reference, ["color"])["color"]
    image = Denoised.load(output).full
    flip_values = frame[frame.metric == "flip"].set_index("entry")["value"]
    assert flip_values["jbf"] == flip(image, truth)
    case = csv.parent / "viewer_case"
    assert sorted(p.name for p in case.glob("jbf_*.png")) == ["jbf_flip.png", "jbf_relmse.png"]
    for name, function, scale in (("flip", flip_map, FLIP_SCALE), ("relmse", relmse_map, RELMSE_SCALE)):
        write_indexed_png(tmp_path / f"{name}.png", scale_indices(function(image, truth), scale), scale)
        assert (case / f"jbf_{name}.png").read_bytes() == (tmp_path / f"{name}.png").read_bytes()


def test_gather_tables_concatenates_the_cases(case_files, tmp_path):
    render, reference = case_files
    first, csv_a, _ = case_metrics(render, reference, tmp_path, scene="box", spp=8)
    second, csv_b, _ = case_metrics(render, reference, tmp_path, scene="room", spp=16)
    out = tmp_path / "metrics.csv"
    frame = evaluation.gather_tables([str(csv_a), str(csv_b)], str(out), entries=[NOISY, "jbf"],
                                metric_names=METRICS, cases=[("box", 8), ("room", 16)])
    expected = pd.concat([first, second], ignore_index=True)
    pd.testing.assert_frame_equal(frame.reset_index(drop=True), expected)
    pd.testing.assert_frame_equal(pd.read_csv(out), expected)


def test_write_rankings_scores_the_lower_error_higher(case_files, tmp_path):
    render, reference = case_files
    frame, csv, _ = case_metrics(render, reference, tmp_path)
    table = rankings.write_rankings(str(csv), "relmse", str(tmp_path / "r.csv"), str(tmp_path / "r.md"),
                                 entries=[NOISY, "jbf"], labels={"jbf": "JBF"})
    # two entries: the lower relMSE scores 2, the other 1 (Sec. 5.3.3)
    assert table.loc["jbf", "Avg."] == 2.0 and table.loc[NOISY, "Avg."] == 1.0
    assert "JBF" in (tmp_path / "r.md").read_text()
    assert set(pd.read_csv(tmp_path / "r.csv")["candidate"]) == {"jbf", NOISY}


def test_gather_timings_collects_and_sorts_the_records(tmp_path):
    records = [{"scene": s, "spp": n, "method": m, "module": m, "kind": "denoiser", "seconds": t,
                "width": 4, "height": 3, "threads": 2, "machine": "test"}
               for s, n, m, t in [("b", 16, "oidn", 0.5), ("a", 8, "oidn", 0.25), ("a", 8, "jbf", 1.0)]]
    paths = []
    for i, record in enumerate(records):
        path = tmp_path / f"t{i}.json"
        path.write_text(json.dumps(record))
        paths.append(str(path))
    out = tmp_path / "timings.csv"
    frame = evaluation.gather_timings(paths, str(out))
    assert list(frame.columns) == ["scene", "spp", "method", "module", "kind", "seconds", "width",
                                   "height", "threads", "machine"]
    assert list(zip(frame["method"], frame["scene"], frame["seconds"])) == [
        ("jbf", "a", 1.0), ("oidn", "a", 0.25), ("oidn", "b", 0.5)]
    pd.testing.assert_frame_equal(pd.read_csv(out), frame.reset_index(drop=True))


def test_merge_reference_is_the_spp_weighted_mean(tmp_path):
    """Two chunks of 64 and 192 spp: colour, features and the second moment pool with weights
    1/4 and 3/4; variance of the mean = (M2 - mean^2) / (N - 1) with N = 256."""
    rng = np.random.default_rng(3)
    h, w = 5, 6
    chunks, paths = [], []
    for index, spp in enumerate((64, 192)):
        color = rng.uniform(0.1, 1.0, (h, w, 3))
        layers = {"color": color, "color_m2": color ** 2 + rng.uniform(0.01, 0.1, (h, w, 3)),
                  "albedo": rng.uniform(0, 1, (h, w, 3)), "normal": rng.uniform(-1, 1, (h, w, 3)),
                  "depth": rng.uniform(1, 5, (h, w))}
        layers = {k: v.astype(np.float32) for k, v in layers.items()}
        path = tmp_path / f"chunk{index}.exr"
        write_layers(path, layers, metadata={"scene": SCENE, "spp": spp, "chunk": index,
                                             "seeds": str(100 + index), "seconds": 1.5})
        chunks.append((spp, layers))
        paths.append(str(path))
    out = tmp_path / "reference.exr"
    rendering.merge_reference(paths, str(out))
    merged = read_layers(out)

    def pooled(name):
        return sum(spp * layers[name].astype(np.float64) for spp, layers in chunks) / 256

    mean = pooled("color")
    np.testing.assert_allclose(merged["color"], mean, rtol=1e-6)
    np.testing.assert_allclose(merged["variance"], (pooled("color_m2") - mean ** 2) / 255,
                               rtol=1e-4, atol=1e-9)
    for name in ("albedo", "normal", "depth"):
        np.testing.assert_allclose(merged[name], pooled(name), rtol=1e-6, atol=1e-7)
    meta = read_metadata(out)
    assert meta["spp"] == "256" and meta["chunks"] == "2" and meta["scene"] == SCENE


def test_a_job_of_row_reading_methods_never_reads_an_input_whole(case_files, tmp_path, monkeypatch):
    """A job whose methods all declare reads_rows (the ensemble) reads the render and its inputs
    by rows (no read_layers of those files) and writes what the whole-file path writes."""
    render, _ = case_files
    inputs = [run(name, render, tmp_path, module_name=name)[0] for name in ("jbf", "oidn")]
    assert method_runs.reads_rows([load_method("ensemble")])
    assert not method_runs.reads_rows([load_method("ensemble"), load_method("naive_average")])
    expected = load_method("ensemble").combine(RenderBuffers.load(render), [Denoised.load(p) for p in inputs])
    import mcbench.io.buffers
    import mcbench.io.exr

    def refuse(path, *args, **kwargs):
        raise AssertionError(f"read whole: {path}")
    monkeypatch.setattr(mcbench.io.buffers, "read_layers", refuse)
    monkeypatch.setattr(mcbench.io.exr, "read_layers", refuse)
    output = tmp_path / "ens_rows.exr"
    method_runs.run_methods([{"name": "ens", "module": "ensemble", "params": {}, "input_paths": [str(p) for p in inputs],
                        "exr": str(output), "timing": str(tmp_path / "ens_rows.json")}], str(render))
    monkeypatch.undo()
    layers = read_layers(output)
    for name, value in stored_layers(expected).items():
        np.testing.assert_array_equal(layers[name], value.astype(np.float32))


def test_an_added_metric_is_the_only_one_computed_and_a_changed_file_recomputes_all(case_files, tmp_path,
                                                                                 monkeypatch):
    """evaluate_entry with a values record: the metric list [relmse] then [relmse, smape, dssim]
    computes relMSE once and each added metric once, with the values of a from-scratch
    evaluation; a rewritten image, a record of other metric code, or a damaged record recompute."""
    import dataclasses
    import sys

    from mcbench.io.file_cache import clear_cache

    render, reference = case_files
    output, _ = run("jbf", render, tmp_path, module_name="jbf")
    calls = []
    for name in ("relmse", "smape", "dssim"):
        spec = load_metric(name)
        counted = dataclasses.replace(spec, value=lambda image, ref, _f=spec.value, _n=name: calls.append(_n) or _f(image, ref))
        monkeypatch.setattr(sys.modules[f"metrics.{name}"], "METRIC", counted)
    values = tmp_path / "values" / "jbf.json"

    def evaluate(metric_list, folder):
        return evaluation.evaluate_entry(SCENE, SPP, "jbf", str(output), str(reference), metric_list,
                                      metrics_path=str(tmp_path / folder / "jbf.csv"), values_path=str(values))

    first = evaluate(["relmse"], "one")
    second = evaluate(["relmse", "smape", "dssim"], "two")
    assert calls == ["relmse", "smape", "dssim"]                 # relMSE not computed again
    scratch = evaluation.evaluate_entry(SCENE, SPP, "jbf", str(output), str(reference), ["relmse", "smape", "dssim"],
                                     metrics_path=str(tmp_path / "scratch.csv"))
    pd.testing.assert_frame_equal(second, scratch)
    assert second.value.iloc[0] == first.value.iloc[0]
    calls.clear()
    evaluate(["dssim", "relmse"], "three")
    assert calls == []                                           # every value known

    layers = read_layers(output)                                 # the method reran: another image
    write_layers(output, {name: layer * 1.5 for name, layer in layers.items()}, metadata=read_metadata(output))
    clear_cache()
    changed = evaluate(["relmse", "smape"], "four")
    assert calls == ["relmse", "smape"]
    assert changed.value.iloc[0] != second.value.iloc[0]

    calls.clear()
    monkeypatch.setattr(evaluation, "metric_code_digest", lambda name: "other metric code")
    evaluate(["relmse"], "five")
    assert calls == ["relmse"]
    monkeypatch.undo()
    calls.clear()
    values.write_text("{damaged")
    frame = evaluation.evaluate_entry(SCENE, SPP, "jbf", str(output), str(reference), ["relmse"],
                                   metrics_path=str(tmp_path / "six.csv"), values_path=str(values))
    assert frame.value.iloc[0] == changed.value.iloc[0]


def test_a_learned_method_runs_with_the_weights_file_its_job_names(case_files, tmp_path):
    """The weights folder is passed, never read from the environment: two folders holding
    different weights give two outputs, each what the plugin gives with that file, and the case's
    key follows the file's digest (mcbench.pipeline.cases.method_key)."""
    import shutil

    import torch

    from mcbench.io.weights import COMMITTED_WEIGHTS, file_sha256, load_weights
    from mcbench.pipeline.cases import method_key
    from mcbench.pipeline.method_runs import method_function

    render, _ = case_files
    committed, other = tmp_path / "committed", tmp_path / "other"
    committed.mkdir(), other.mkdir()
    shutil.copy(COMMITTED_WEIGHTS / "optix_ae.pt", committed / "optix_ae.pt")
    blob = load_weights(COMMITTED_WEIGHTS / "optix_ae.pt")
    torch.save({"arch": blob["arch"], "state_dict": {k: v * 0.5 for k, v in blob["state_dict"].items()}},
               other / "optix_ae.pt")
    images = {}
    for folder in (committed, other):
        output, _ = run(f"ae_{folder.name}", render, tmp_path, module_name="optix_ae",
                        weights=str(folder / "optix_ae.pt"))
        images[folder.name] = Denoised.load(str(output)).full
        expected = method_function(load_method("optix_ae"), weights_dir=folder)(RenderBuffers.load(render))
        np.testing.assert_array_equal(images[folder.name], expected.full)
    assert not np.array_equal(images["committed"], images["other"])
    keys = {method_key(module="optix_ae", params={}, input_keys=[], weights_sha256=file_sha256(folder / "optix_ae.pt"),
                       render="r") for folder in (committed, other)}
    assert len(keys) == 2
    with pytest.raises(BenchError, match="'ae_none' is a learned method, but its job names no weights file"):
        run("ae_none", render, tmp_path, module_name="optix_ae")
