"""Scenes of renders made elsewhere (scenes/<name>.yaml) in the pipeline: checked when the DAG is
parsed (every case, the reference, each method's layers), imported in place of rendering, ranked
with a single-image denoiser, refused with a clear message for methods that need what the folder
lacks. Synthetic images with known pixels; the metric is recomputed from them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

import scenes
from mcbench import BenchError
from mcbench.analysis.metrics import relmse
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.case_folders import write_image
from mcbench.io.exr import read_metadata
from mcbench.pipeline.config import resolve_config
from mcbench.pipeline.plan import plan_study

H, W = 24, 20


def write_oidn_folder(root, stem):
    rng = np.random.default_rng(7)
    ramp = np.linspace(0.2, 1.0, W, dtype=np.float32)       # smooth: a denoiser should gain on it
    reference = np.broadcast_to(ramp[None, :, None], (H, W, 3)).copy()
    for spp in (4, 16):
        noisy = (reference * rng.gamma(spp, 1.0 / spp, (H, W, 3))).astype(np.float32)
        write_image(root / f"{stem}_{spp:04d}.hdr.exr", noisy)
        write_image(root / f"{stem}_{spp:04d}.alb.exr", np.full((H, W, 3), 0.5, np.float32))
        normal = np.zeros((H, W, 3), np.float32)
        normal[..., 2] = 1.0
        write_image(root / f"{stem}_{spp:04d}.nrm.exr", normal)
    write_image(root / f"{stem}_ref.hdr.exr", reference)


def write_authors_folder(root):
    rng = np.random.default_rng(8)
    reference = rng.uniform(0.2, 1.0, (H, W, 3)).astype(np.float32)
    for spp in (4, 16):
        case = root / f"spp{spp}"
        for name in ("colorA", "colorB"):
            write_image(case / f"{name}.exr", (reference * rng.gamma(spp / 2, 2.0 / spp, (H, W, 3))).astype(np.float32))
            write_image(case / f"variance{name[-1]}.exr", np.full((H, W, 3), 0.1, np.float32))
        write_image(case / "variance.exr", np.full((H, W, 3), 0.05, np.float32))
        write_image(case / "albedo.exr", np.full((H, W, 3), 0.5, np.float32))
        write_image(case / "normal.exr", np.dstack([np.zeros((H, W, 2)), np.ones((H, W))]).astype(np.float32))
        write_image(case / "depth.exr", np.full((H, W), 2.0, np.float32))
    write_image(root / "reference.exr", reference)
    write_image(root / "reference_variance.exr", np.full((H, W, 3), 1e-6, np.float32))


@pytest.fixture
def folder_scenes(tmp_path, monkeypatch):
    """Two scene files in a scenes folder searched before the package's own: ``kitchen`` (OIDN
    naming: colour, albedo, normal only) and ``attic`` (the authors' layout with every layer)."""
    scene_dir = tmp_path / "scenes"
    scene_dir.mkdir()
    write_oidn_folder(tmp_path / "oidn", "kitchen")
    write_authors_folder(tmp_path / "authors")
    (scene_dir / "kitchen.yaml").write_text("renders: ../oidn\nlayout: oidn\ndescription: OIDN-named renders\n")
    (scene_dir / "attic.yaml").write_text(f"renders: {tmp_path / 'authors'}\nlayout: authors\n")
    monkeypatch.setattr(scenes, "__path__", [str(scene_dir), *scenes.__path__])
    return tmp_path


def plan(**overrides):
    config = {"scenes": ["cornell_box", "kitchen"], "spp": [4, 16], "denoisers": ["oidn"], "combiners": [],
              "study": {"pool": False}, "metrics": ["relmse", "smape"],
              "reference": {"spp": 64, "chunks": 1}, "oracle": {"spp": 4, "repetitions": 2, "denoisers": ["oidn", "jbf"]}}
    config.update(overrides)
    return plan_study(resolve_config(config), written=config, source="test.yaml")


def test_a_single_image_denoiser_is_planned_on_renders_without_halves(folder_scenes):
    result = plan()
    assert set(result.cases.render_folders) == {"kitchen"} and result.cases.reference_spp["kitchen"] is None
    assert result.side.oracle_scene == "cornell_box"
    assert plan(scenes=["kitchen", "cornell_box"]).side.oracle_scene == "cornell_box"   # the first one rendered
    assert plan(scenes=["kitchen"]).side.oracle_scene is None


@pytest.mark.parametrize("overrides, message", [
    ({"denoisers": ["oidn", "jbf"]},
     r"method 'jbf' \(jbf\) reads render layer\(s\) \['variance', 'depth'\], which scene "
     r"'kitchen' lacks .*supply variance.exr, depth.exr in the authors' layout"),
    ({"denoisers": ["oidn", "nfor"]}, r"method 'nfor' \(nfor\) reads render layer\(s\) \['color_a'"),
    ({"combiners": [{"name": "ens", "method": "ensemble", "inputs": ["oidn", "oidn_fast"]}],
      "denoisers": ["oidn", {"name": "oidn_fast", "method": "oidn", "params": {"quality": "fast"}}]},
     r"method 'ens' \(ensemble\) reads render layer\(s\) \['color_a', 'color_b'\]"),
    ({"metrics": ["relmse", "relmse_corrected"]}, r"relmse_corrected needs the reference's variance"),
    ({"oracle": {"scene": "kitchen"}}, r"oracle.scene: 'kitchen' is a scene of renders made elsewhere"),
    ({"resolution": [32, 32]}, r"resolution: \[32, 32\], but the renders of scene 'kitchen' are 20x24"),
    ({"spp": [4, 8]}, r"the case at 8 spp \(spp lists it\) lacks .*kitchen_8.hdr.exr"),
])
def test_what_the_folder_lacks_is_refused_when_the_dag_is_parsed(folder_scenes, overrides, message):
    with pytest.raises(BenchError, match=message):
        plan(**overrides)


def test_a_folder_with_every_layer_takes_every_method(folder_scenes):
    # the authors' layout holds no feature variances: NFOR's default (Tungsten's, feature_variance
    # 'buffer') reads them and is refused when the DAG is parsed; its 'halves' estimator runs
    with pytest.raises(BenchError, match=r"method 'nfor' \(nfor\) reads render layer\(s\) \['normal_variance', "
                                         r"'albedo_variance', 'depth_variance'\], which scene 'attic' lacks"):
        plan(scenes=["cornell_box", "attic"], denoisers=["oidn", "nfor"])
    nfor = {"name": "nfor", "method": "nfor", "params": {"feature_variance": "halves"}}
    result = plan(scenes=["cornell_box", "attic"], denoisers=["oidn", "jbf", nfor],
                  combiners=[{"name": "ens", "method": "ensemble", "inputs": ["oidn", "nfor"]}],
                  metrics=["relmse", "relmse_corrected"])
    assert list(result.cases.render_folders) == ["attic"]
    (folder_scenes / "authors" / "spp16" / "colorB.exr").unlink()
    with pytest.raises(BenchError, match=r"the case at 16 spp .* lacks .*spp16/colorB.exr"):
        plan(scenes=["cornell_box", "attic"])


def test_imported_case_is_denoised_and_scored_like_a_render(folder_scenes, tmp_path):
    from mcbench.pipeline.cases import run_case
    from mcbench.pipeline.rendering import merge_reference, render_noisy
    from tests.conftest import case_job

    render, reference = tmp_path / "render.exr", tmp_path / "reference.exr"
    render_noisy("kitchen", 16, str(render))
    merge_reference([], str(reference), scene="kitchen")
    buffers = RenderBuffers.load(render)
    assert set(buffers.layers) == {"color", "albedo", "normal"} and buffers.spp == 16
    assert read_metadata(render)["imported_from"] == str((folder_scenes / "oidn").resolve())
    with pytest.raises(BenchError, match="no image 'a'"):
        buffers.image("a")
    case = tmp_path / "case"
    run_case(case_job(case, scene="kitchen", spp=16, render=render, reference=reference, metrics=["relmse"],
                      methods=[("oidn", "oidn", {}, [])]))
    output = Denoised.load(case / "outputs" / "oidn.exr")
    assert output.a is None and output.b is None and output.full.shape == (H, W, 3)
    table = pd.read_csv(case / "case.csv")
    values = table.set_index("entry")["value"]
    from mcbench.io.render_folders import read_image_any
    truth = read_image_any(folder_scenes / "oidn" / "kitchen_ref.hdr.exr")
    noisy = read_image_any(folder_scenes / "oidn" / "kitchen_0016.hdr.exr")
    assert values["noisy"] == pytest.approx(relmse(noisy, truth), rel=1e-12)
    assert values["oidn"] == pytest.approx(relmse(output.full, truth), rel=1e-12)
    assert values["oidn"] < values["noisy"]
    assert list(table.entry) == ["noisy", "oidn"]


@pytest.mark.extended     # a whole scratch study (75 s): beside the worked example's end-to-end run
def test_a_study_ranks_renders_from_another_renderer_end_to_end(tmp_path):
    """A scratch copy of the workflow with two scene files of renders made elsewhere (OIDN naming
    without halves, the authors' layout with every layer) beside a Mitsuba scene, 32 x 32: the
    cases and references are imported, OIDN runs on all three, the rankings and the scene table
    are written, and each imported case's relMSE is the one recomputed from the folder's files."""
    import os
    import shutil
    import subprocess
    import sys

    from mcbench.io.render_folders import read_image_any
    from tests.conftest import REPO

    copy = tmp_path / "repo"
    copy.mkdir()
    for name in ("Snakefile", "config.yaml", "pyproject.toml"):
        shutil.copy(REPO / name, copy / name)
    for name in ("workflow", "mcbench", "methods", "scenes", "metrics"):
        shutil.copytree(REPO / name, copy / name, ignore=shutil.ignore_patterns("__pycache__"))
    global H, W
    H, W = 32, 32
    try:
        write_oidn_folder(tmp_path / "oidn", "kitchen")
        write_authors_folder(tmp_path / "authors")
    finally:
        H, W = 24, 20
    (copy / "scenes" / "kitchen.yaml").write_text(f"renders: {tmp_path / 'oidn'}\nlayout: oidn\n")
    (copy / "scenes" / "attic.yaml").write_text(f"renders: {tmp_path / 'authors'}\nlayout: authors\n")
    config = ("scenes: [cornell_box, kitchen, attic]\nspp: [4, 16]\nresolution: [32, 32]\ndenoisers: [oidn]\n"
              "combiners: []\nstudy: {pool: false}\nmetrics: [relmse, smape, dssim]\n"
              "reference: {spp: 64, chunks: 1}\noracle: {spp: 4, repetitions: 2, denoisers: [oidn, jbf]}\n")
    (copy / "run.yaml").write_text(config)
    env = dict(os.environ, PYTHONPATH=str(copy))
    result = subprocess.run([sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", "run.yaml"],
                            cwd=copy, env=env, capture_output=True, text=True, timeout=1500)
    assert result.returncode == 0, result.stderr[-4000:]
    metrics = pd.read_csv(copy / "results" / "metrics.csv")
    relmse_rows = metrics[metrics["metric"] == "relmse"].set_index(["scene", "spp", "entry"])["value"]
    truth = read_image_any(tmp_path / "oidn" / "kitchen_ref.hdr.exr")
    noisy = read_image_any(tmp_path / "oidn" / "kitchen_0004.hdr.exr")
    assert relmse_rows[("kitchen", 4, "noisy")] == pytest.approx(relmse(noisy, truth), rel=1e-9)
    halves = [read_image_any(tmp_path / "authors" / "spp16" / f"color{h}.exr") for h in "AB"]
    truth = read_image_any(tmp_path / "authors" / "reference.exr")
    assert relmse_rows[("attic", 16, "noisy")] == pytest.approx(relmse((halves[0] + halves[1]) / 2, truth), rel=1e-9)
    assert {"cornell_box", "kitchen", "attic"} <= set(metrics["scene"])
    scenes_md = (copy / "results" / "tables" / "scenes.md").read_text()
    assert "kitchen" in scenes_md and "n/a" in scenes_md      # no reference variance: floor unknown
    assert (copy / "results" / "tables" / "ranking_relmse.md").is_file()


def test_a_combiner_is_refused_without_halves_even_if_it_reads_no_render_layer_of_them(folder_scenes, monkeypatch):
    """A combiner weighs its inputs by their half-buffer results, which a render without halves
    cannot give, whatever render layers it declares."""
    import methods.naive_average

    monkeypatch.setattr(methods.naive_average, "METHOD",
                        dataclasses.replace(methods.naive_average.METHOD, render_layers=("color",)))
    combiners = [{"name": "avg", "method": "naive_average", "inputs": ["oidn", "oidn_fast"]}]
    denoisers = ["oidn", {"name": "oidn_fast", "method": "oidn", "params": {"quality": "fast"}}]
    with pytest.raises(BenchError, match=r"method 'avg' \(naive_average\) reads render layer\(s\) \['color_a', 'color_b'\]"):
        plan(denoisers=denoisers, combiners=combiners)
    assert plan(scenes=["cornell_box", "attic"], denoisers=denoisers, combiners=combiners).cases.render_folders
