"""``method: precomputed`` (methods/precomputed.py): results made elsewhere, read by a pattern,
checked like any method output, and every case's files checked when the DAG is parsed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.io.case_folders import result_files, write_image
from mcbench.io.exr import read_layers, write_layers
from mcbench.pipeline.method_runs import run_methods
from mcbench.pipeline.plan import _check_case_files
from methods import check_params, load_method


@pytest.fixture
def case(tmp_path, make_render_buffers):
    buffers = make_render_buffers(spp=8, half_std=0.1, seed=4, height=6, width=8)
    render = tmp_path / "render.exr"
    write_layers(render, buffers.layers, metadata={"spp": 8, "scene": "box", "resolution": "8x6"})
    rng = np.random.default_rng(5)
    results = {image: rng.uniform(0, 1, (6, 8, 3)).astype(np.float32) for image in ("full", "a", "b")}
    for image, path in result_files("{dir}/{scene}/spp{spp}/{name}/{name}{image}.exr", dir=str(tmp_path / "made"),
                                    scene="box", spp=8, name="gpu").items():
        write_image(path, results[image])
    return render, results


def run(render, tmp_path, params):
    output, timing = tmp_path / "gpu.exr", tmp_path / "gpu.json"
    run_methods([{"name": "gpu", "module": "precomputed", "params": params, "input_paths": [], "exr": str(output),
                  "timing": str(timing)}], str(render), scene="box", spp=8)
    return read_layers(output), json.loads(timing.read_text())


def test_precomputed_results_are_read_by_the_pattern(case, tmp_path):
    render, results = case
    layers, timing = run(render, tmp_path, {"dir": str(tmp_path / "made"), "seconds": 1.5})
    for layer, image in (("color", "full"), ("color_a", "a"), ("color_b", "b")):
        assert np.array_equal(layers[layer], results[image])
    assert timing["seconds"] == 1.5           # the time measured where they were made


def test_a_damaged_result_is_refused_naming_the_file(case, tmp_path):
    render, _ = case
    path = tmp_path / "made" / "box" / "spp8" / "gpu" / "gpuA.exr"
    write_image(path, np.zeros((5, 8, 3)))
    with pytest.raises(ValueError, match=r"gpuA.exr: precomputed result is \(5, 8, 3\)"):
        run(render, tmp_path, {"dir": str(tmp_path / "made")})
    path.write_bytes(b"junk")
    with pytest.raises(Exception, match="gpuA.exr"):
        run(render, tmp_path, {"dir": str(tmp_path / "made")})


def test_missing_cases_are_named_when_the_dag_is_parsed(case, tmp_path):
    methods = {"gpu": {"module": "precomputed", "params": {"dir": str(tmp_path / "made")}}}
    _check_case_files(methods, ["box"], [8])                       # all present
    with pytest.raises(BenchError, match=r"method 'gpu' \(precomputed\): 3 file\(s\).*box/spp64/gpu/gpu.exr"):
        _check_case_files(methods, ["box"], [8, 64])


def test_bad_params_stop_at_parse_time():
    module = load_method("precomputed")
    with pytest.raises(BenchError, match="needs parameter"):
        check_params(module, {}, config_key="denoisers[4].params")
    with pytest.raises(BenchError, match=r"denoisers\[4\]\.params\.pattern.*\{image\}"):
        check_params(module, {"dir": "x", "pattern": "{dir}/{scene}.exr"}, config_key="denoisers[4].params")
    with pytest.raises(BenchError, match=r"unknown: \['method'\]"):
        check_params(module, {"dir": "x", "pattern": "{dir}/{method}{image}.exr"}, config_key="denoisers[4].params")
    with pytest.raises(BenchError, match="seconds"):
        check_params(module, {"dir": "x", "seconds": -1}, config_key="denoisers[4].params")
