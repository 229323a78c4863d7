"""Fast tests of the static image viewer (mcbench.analysis.viewer_images, the viewer steps and the page's DOM
contract) on synthetic arrays and tiny EXRs written here; the browser test is in test_report.py.

Independent truths: the ACES + sRGB closed form written out below, the relMSE formula, NVIDIA's
flip_evaluator called directly, decoded PNG/JPEG pixels, and metric values planted in a CSV."""

from __future__ import annotations

import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from mcbench import BenchError
from mcbench.analysis import viewer_images as viewer
from mcbench.pipeline import viewer as viewer_step
from mcbench.io.exr import write_layers
from tests.conftest import case_job

PAGE = Path(__file__).resolve().parents[2] / "workflow" / "report" / "viewer"


def aces_srgb(x):
    """Narkowicz's ACES fit then the sRGB curve, written out (IEC 61966-2-1)."""
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    a = np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    return np.where(a <= 0.0031308, 12.92 * a, 1.055 * a ** (1 / 2.4) - 0.055)


def radiance(height=8, width=12, seed=0):
    """Linear HDR radiance spanning darks to highlights: log-uniform in [1e-3, 20]."""
    rng = np.random.default_rng(seed)
    return 10.0 ** rng.uniform(-3.0, math.log10(20.0), size=(height, width, 3))


def smooth_radiance(height, width, *, scale=1.0):
    """Radiance whose display values change by a few levels per pixel (JPEG keeps it closely)."""
    y, x = np.mgrid[0:height, 0:width]
    x, y = x / max(width - 1, 1), y / max(height - 1, 1)
    return scale * (0.1 + np.stack([x, y, 0.5 * (x + y)], axis=-1))


def decoded(path) -> np.ndarray:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB")).astype(np.int64)


def palette_indices(path) -> np.ndarray:
    """Indices of an indexed PNG recovered from its decoded colours through its own palette
    (nearest palette colour: equal colours map back exactly)."""
    with Image.open(path) as image:
        assert image.mode == "P"
        colours = np.asarray(image.getpalette()[:3 * viewer.LEVELS]).reshape(-1, 3)
        rgb = np.asarray(image.convert("RGB")).astype(np.int64)
    distance = ((rgb[:, :, None, :] - colours[None, None]) ** 2).sum(axis=-1)
    return distance.argmin(axis=-1)


# --- tone mapping and exposure --------------------------------------------------------------

def test_display_at_ev0_is_the_dssim_tone_mapping():
    image = radiance()
    np.testing.assert_allclose(viewer.exposed_display(image, ev=0), aces_srgb(image), rtol=0, atol=1e-12)


@pytest.mark.parametrize("ev", [-2, -1, 1, 2])
def test_exposure_multiplies_radiance_by_two_to_the_ev_before_tone_mapping(ev):
    image = radiance(seed=ev + 5)
    np.testing.assert_allclose(viewer.exposed_display(image, ev=ev), aces_srgb(image * 2.0 ** ev),
                               rtol=0, atol=1e-12)
    brighter = viewer.exposed_display(image, ev=ev + 1) >= viewer.exposed_display(image, ev=ev)
    assert brighter.all()


def test_display_bytes_round_to_eight_bits():
    values = np.array([0.0, 1 / 255, 0.5 / 255 - 1e-9, 0.499, 1.0, 1.2, -0.1])
    np.testing.assert_array_equal(viewer.display_bytes(values), [0, 1, 0, 127, 255, 255, 0])


def test_jpeg_holds_the_tone_mapped_image(tmp_path):
    image = smooth_radiance(32, 48)
    expected = viewer.display_bytes(aces_srgb(image * 2.0))
    viewer.write_jpeg(tmp_path / "a.jpg", viewer.display_bytes(viewer.exposed_display(image, ev=1)))
    pixels = decoded(tmp_path / "a.jpg")
    assert pixels.shape == (32, 48, 3)
    assert np.abs(pixels - expected).mean() < 1.5
    assert np.abs(pixels - expected).max() <= 8
    from PIL import Image

    rgb = viewer.display_bytes(viewer.exposed_display(image, ev=1))
    Image.fromarray(rgb).save(tmp_path / "standard.jpg", format="JPEG", quality=viewer.JPEG_QUALITY, subsampling=0)
    assert np.array_equal(pixels, decoded(tmp_path / "standard.jpg"))     # optimised tables: the same pixels
    assert (tmp_path / "a.jpg").stat().st_size < (tmp_path / "standard.jpg").stat().st_size


def test_exposure_tags_are_distinct_file_name_safe():
    tags = [viewer.exposure_tag(ev) for ev in viewer.EXPOSURES_EV]
    assert tags == ["evm2", "evm1", "ev0", "evp1", "evp2"]
    assert all(re.fullmatch(r"[a-z0-9]+", tag) for tag in tags)


# --- colour scales ----------------------------------------------------------------------------

def luminance(colours):
    return np.asarray(colours, np.float64) @ [0.2126, 0.7152, 0.0722]


@pytest.mark.parametrize("scale", [viewer.RELMSE_SCALE, viewer.FLIP_SCALE, viewer.WEIGHT_SCALE])
def test_palettes_are_perceptual_maps_dark_to_bright(scale):
    colours = viewer.palette(scale)
    assert colours.shape == (viewer.LEVELS, 3) and colours.dtype == np.uint8
    assert np.all(np.diff(luminance(colours)) > 0)                 # monotone: low is dark
    assert len({tuple(c) for c in colours}) == viewer.LEVELS       # every level its own colour


@pytest.mark.parametrize("scale", [viewer.RELMSE_SCALE, viewer.FLIP_SCALE, viewer.WEIGHT_SCALE])
def test_map_colours_round_trip_to_values_within_half_a_level(scale, tmp_path):
    rng = np.random.default_rng(3)
    if scale.log:
        values = 10.0 ** rng.uniform(math.log10(scale.low), math.log10(scale.high), size=(20, 30))
    else:
        values = rng.uniform(scale.low, scale.high, size=(20, 30))
    viewer.write_indexed_png(tmp_path / "map.png", viewer.scale_indices(values, scale), scale)
    back = viewer.index_values(palette_indices(tmp_path / "map.png"), scale)
    half_level = 0.5 / viewer.LEVELS
    if scale.log:
        span = math.log10(scale.high) - math.log10(scale.low)
        error = np.abs(np.log10(back) - np.log10(values)) / span
    else:
        error = np.abs(back - values) / (scale.high - scale.low)
    assert error.max() <= half_level + 1e-12


def test_values_outside_a_scale_take_the_end_colours():
    scale = viewer.RELMSE_SCALE
    indices = viewer.scale_indices(np.array([0.0, 1e-9, scale.low, scale.high, 1e6]), scale)
    np.testing.assert_array_equal(indices, [0, 0, 0, viewer.LEVELS - 1, viewer.LEVELS - 1])
    with pytest.raises(ValueError, match="NaN or Inf"):
        viewer.scale_indices(np.array([np.nan]), scale)


def test_log_scale_ticks_sit_at_their_decades():
    ticks = viewer.scale_ticks(viewer.RELMSE_SCALE)          # 1e-5 ... 1e1: six decades
    assert [t["value"] for t in ticks] == pytest.approx([1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0])
    assert [t["position"] for t in ticks] == pytest.approx([k / 6 for k in range(7)])
    linear = viewer.scale_ticks(viewer.FLIP_SCALE)
    assert [t["value"] for t in linear] == pytest.approx([0, 0.25, 0.5, 0.75, 1])
    assert [t["position"] for t in linear] == pytest.approx([0, 0.25, 0.5, 0.75, 1])


def test_legend_is_the_maps_palette_from_low_to_high(tmp_path):
    viewer.write_indexed_png(tmp_path / "legend.png", viewer.legend_indices(width=256, height=2),
                             viewer.FLIP_SCALE)
    indices = palette_indices(tmp_path / "legend.png")
    assert indices.shape == (2, 256)
    assert indices[0, 0] == 0 and indices[0, -1] == viewer.LEVELS - 1
    assert np.all(np.diff(indices[0]) >= 0) and len(set(indices[0])) == viewer.LEVELS
    colours = decoded(tmp_path / "legend.png")[0]
    np.testing.assert_array_equal(colours[::256 // viewer.LEVELS], viewer.palette(viewer.FLIP_SCALE))


# --- weight maps and error maps ---------------------------------------------------------------

def test_weight_map_is_the_rgb_mean_clamped_to_the_simplex():
    layer = np.zeros((2, 3, 3))
    layer[0, 0] = [0.2, 0.4, 0.9]
    layer[0, 1] = [1 + 1e-7, 1 + 1e-7, 1 + 1e-7]
    layer[1, 2] = [-1e-7, 0.0, 0.0]
    expected = np.zeros((2, 3))
    expected[0, 0], expected[0, 1] = 0.5, 1.0
    np.testing.assert_allclose(viewer.weight_map(layer), expected, atol=1e-15)
    # a stored output keeps the mean itself (mcbench.io.buffers.stored_layers): the same map
    np.testing.assert_allclose(viewer.weight_map(layer.mean(axis=2)), expected, atol=1e-15)
    with pytest.raises(ValueError, match=r"\(H, W, 3\) or \(H, W\)"):
        viewer.weight_map(np.zeros((2, 3, 2)))


def test_a_stored_output_keeps_what_later_steps_read(tmp_path):
    """Stored layers of a combiner result: colour, halves and sub-buffer results bit for bit, the
    filtered weights as their RGB mean (what the viewer shows), the raw weights and the other
    extras (read by no step) left out; the file written from them loads back as the same output
    and the same weight maps."""
    from mcbench.io.buffers import Denoised, stored_layers
    from mcbench.io.exr import write_layers

    rng = np.random.default_rng(3)
    images = [rng.random((4, 5, 3)).astype(np.float32) for _ in range(3)]
    filtered = rng.dirichlet([1, 1], size=(4, 5, 3)).astype(np.float32)    # (4, 5, 3, 2) on the simplex
    extras = {**{f"weights_raw_{i}": filtered[..., i] * 2 for i in range(2)},
              **{f"weights_filtered_{i}": filtered[..., i] for i in range(2)},
              "color_sub0": images[0] * 0.5, "alpha": images[1][..., 0], "selection": images[2]}
    result = Denoised(full=images[0], a=images[1], b=images[2], extras=extras)
    kept = stored_layers(result)
    assert sorted(kept) == ["color", "color_a", "color_b", "color_sub0", "weights_filtered_0", "weights_filtered_1"]
    for name in ("color", "color_a", "color_b", "color_sub0"):
        assert np.array_equal(kept[name], result.layers()[name])
    write_layers(tmp_path / "out.exr", kept)
    loaded = Denoised.load(tmp_path / "out.exr", extras=True)
    assert np.array_equal(loaded.full, images[0]) and np.array_equal(loaded.b, images[2])
    for i in range(2):
        np.testing.assert_allclose(viewer.weight_map(loaded.extras[f"weights_filtered_{i}"]),
                                   viewer.weight_map(filtered[..., i]), atol=1e-7)


def test_error_maps_are_relmse_and_hdr_flip_of_the_pair():
    """The case job's error maps (mcbench.pipeline.evaluation.entry_metrics): one per metric that
    declares a map, on its scale, in the config's order; relMSE's closed form and NVIDIA's
    flip_evaluator called directly."""
    import flip_evaluator

    from mcbench.pipeline.evaluation import entry_metrics
    from mcbench.pipeline.registry import load_metrics

    reference = radiance(24, 24, seed=1)
    image = reference * np.random.default_rng(2).gamma(8.0, 1 / 8.0, size=reference.shape)
    values, maps = entry_metrics(load_metrics(["relmse", "smape", "flip"]), image, reference, maps=True)
    assert list(values) == ["relmse", "smape", "flip"] and list(maps) == ["relmse", "flip"]
    assert maps["relmse"][0] == viewer.RELMSE_SCALE and maps["flip"][0] == viewer.FLIP_SCALE
    np.testing.assert_allclose(maps["relmse"][1], ((image - reference) ** 2 / (reference ** 2 + 0.01)).mean(axis=2),
                               rtol=1e-12)
    package, mean, _ = flip_evaluator.evaluate(reference.astype(np.float32), image.astype(np.float32), "HDR",
                                               applyMagma=False, computeMeanError=True)
    # within the package's float32 rounding (tests/analysis/test_hdr_flip.py)
    np.testing.assert_allclose(maps["flip"][1], np.asarray(package).reshape(24, 24), atol=1e-5)
    assert values["flip"] == pytest.approx(mean, rel=5e-6)


# --- one case's images ------------------------------------------------------------------------

def stand_in_maps(height, width) -> dict:
    """Error maps with known values (pixel index scaled into each scale), so files can be checked
    without FLIP's cost: {metric: (scale, (H, W) values)}."""
    ramp = np.arange(height * width).reshape(height, width) / (height * width - 1)
    return {"relmse": (viewer.RELMSE_SCALE, 10.0 ** (-5 + 6 * ramp)), "flip": (viewer.FLIP_SCALE, ramp)}


def test_case_images_files_and_fragment(tmp_path):
    height, width = 24, 40
    reference = smooth_radiance(height, width)
    images = {"noisy": reference * 1.5, "ens": reference * 0.9}
    weight = np.full((height, width, 3), 0.25)
    fragment = viewer.write_case_images(tmp_path, reference=reference, images=images,
                                        weights={"ens": [("a", weight), ("b", 1 - weight)]},
                                        error_maps={name: stand_in_maps(height, width) for name in images})
    assert (fragment["width"], fragment["height"]) == (width, height)
    assert list(fragment["images"]) == ["reference", "noisy", "ens"]
    for entry, image in {"reference": reference, **images}.items():
        assert sorted(fragment["images"][entry], key=int) == [str(ev) for ev in viewer.EXPOSURES_EV]
        pixels = decoded(tmp_path / fragment["images"][entry]["1"])
        assert np.abs(pixels - viewer.display_bytes(aces_srgb(2.0 * image))).mean() < 2
    assert "reference" not in fragment["errors"]
    assert {name: list(files) for name, files in fragment["errors"].items()} == {"noisy": ["relmse", "flip"],
                                                                               "ens": ["relmse", "flip"]}
    flip_indices = palette_indices(tmp_path / fragment["errors"]["noisy"]["flip"])
    ramp = np.arange(height * width).reshape(height, width) / (height * width - 1)
    np.testing.assert_array_equal(flip_indices, np.minimum(np.floor(ramp * viewer.LEVELS), viewer.LEVELS - 1))
    relmse_values = viewer.index_values(palette_indices(tmp_path / fragment["errors"]["ens"]["relmse"]),
                                        viewer.RELMSE_SCALE)
    assert np.abs(np.log10(relmse_values) - (-5 + 6 * ramp)).max() <= 6 * 0.5 / viewer.LEVELS + 1e-12
    assert [w["input"] for w in fragment["weights"]["ens"]] == ["a", "b"]
    weights = [viewer.index_values(palette_indices(tmp_path / w["file"]), viewer.WEIGHT_SCALE)
               for w in fragment["weights"]["ens"]]
    np.testing.assert_allclose(weights[0], 0.25, atol=0.5 / viewer.LEVELS)
    np.testing.assert_allclose(weights[1], 0.75, atol=0.5 / viewer.LEVELS)


def test_case_images_refuse_bad_input(tmp_path):
    reference = radiance(4, 4)
    with pytest.raises(BenchError, match="'jbf' has shape"):
        viewer.write_case_images(tmp_path, reference=reference, images={"jbf": np.zeros((4, 5, 3))})
    with pytest.raises(BenchError, match="'jbf' holds NaN"):
        viewer.write_case_images(tmp_path, reference=reference, images={"jbf": np.full((4, 4, 3), np.nan)})
    with pytest.raises(BenchError, match="reserved|entry name"):
        viewer.write_case_images(tmp_path, reference=reference, images={"reference": reference})
    with pytest.raises(BenchError, match="flip map of 'jbf' is"):
        viewer.write_case_images(tmp_path, reference=reference, images={"jbf": reference},
                                 error_maps={"jbf": {"flip": (viewer.FLIP_SCALE, np.zeros((4, 5)))}})


# --- manifest ---------------------------------------------------------------------------------

def metrics_frame(cases, entries, metric_names):
    """A tidy metrics table with distinct planted values: 1000 * case + 10 * entry + metric."""
    rows = [{"scene": scene, "spp": spp, "entry": entry, "metric": metric,
             "value": 1000.0 * c + 10.0 * e + m}
            for c, (scene, spp) in enumerate(cases) for e, entry in enumerate(entries)
            for m, metric in enumerate(metric_names)]
    return pd.DataFrame(rows)


def test_case_numbers_come_from_the_metrics_table():
    frame = metrics_frame([("box", 4), ("box", 16)], ["noisy", "jbf"], ["relmse", "flip"])
    numbers = viewer.case_numbers(frame, scene="box", spp=16, entries=["noisy", "jbf"], metric_names=["relmse", "flip"])
    assert numbers == {"noisy": {"relmse": 1000.0, "flip": 1001.0}, "jbf": {"relmse": 1010.0, "flip": 1011.0}}
    with pytest.raises(BenchError, match=r"m\.csv: no single finite dssim of 'jbf' for \(box, 16\)"):
        viewer.case_numbers(frame, scene="box", spp=16, entries=["jbf"], metric_names=["dssim"], source="m.csv")


def test_manifest_script_is_one_assignment_of_json_and_refuses_nan():
    text = viewer.manifest_script({"a": [1, 2.5], "b": "x"})
    assert text.startswith("window.MCBENCH_VIEWER = ") and text.endswith(";\n")
    assert json.loads(text[len("window.MCBENCH_VIEWER = "):-2]) == {"a": [1, 2.5], "b": "x"}
    with pytest.raises(ValueError):
        viewer.manifest_script({"a": float("nan")})


# --- the steps: a synthetic results folder ---------------------------------------------------

SCENES, SPPS = ["box", "room"], [4, 16]
CANDIDATES = ["jbf", "ens"]
LABELS = {"noisy": "Noisy input", "jbf": "JBF", "ens": "Ensemble (jbf+oidn)", "oidn": "OIDN"}
METRIC_NAMES = ["relmse", "flip"]


@pytest.fixture
def results(tmp_path, make_render_buffers):
    """EXRs of 2 scenes x 2 spp at 16 x 16 (render, reference, a denoiser and an ensemble with
    two weight maps) and a metrics.csv with planted values."""
    paths = {}
    for s, scene in enumerate(SCENES):
        truth = make_render_buffers(half_std=0.0).color.astype(np.float64) * (1 + s)
        reference = tmp_path / "references" / f"{scene}.exr"
        write_layers(reference, {"color": truth, "variance": np.zeros_like(truth)})
        for spp in SPPS:
            buffers = make_render_buffers(truth=truth, spp=spp, half_std=0.5 / math.sqrt(spp), seed=spp + s)
            render = tmp_path / "renders" / scene / f"spp{spp}.exr"
            write_layers(render, buffers.layers)
            outputs = tmp_path / "outputs" / scene / f"spp{spp}"
            smooth = 0.5 * (buffers.color + truth)
            write_layers(outputs / "jbf.exr", {"color": smooth, "color_a": smooth, "color_b": smooth})
            w = np.full(truth.shape, 0.3)
            write_layers(outputs / "ens.exr", {"color": truth, "color_a": truth, "color_b": truth,
                                                "weights_raw_0": w, "weights_raw_1": 1 - w,
                                                "weights_filtered_0": w, "weights_filtered_1": 1 - w})
            paths[(scene, spp)] = {"reference": str(reference), "render": str(render),
                                   "candidates": {name: str(outputs / f"{name}.exr") for name in CANDIDATES}}
    metrics_csv = tmp_path / "metrics.csv"
    cases = [(scene, spp) for scene in SCENES for spp in SPPS]
    metrics_frame(cases, ["noisy"] + CANDIDATES, METRIC_NAMES).to_csv(metrics_csv, index=False)
    return tmp_path, paths, str(metrics_csv), cases


def case_folder(root, scene, spp, files, *, weight_inputs=None) -> Path:
    """The case job (rule run_case's code) on a case's files: its folder, whose ``viewer_case``
    is the case's viewer folder."""
    from mcbench.pipeline.cases import run_case

    folder = root / "cases" / scene / f"spp{spp}"
    run_case(case_job(folder, scene=scene, spp=spp, render=files["render"], reference=files["reference"],
                      metrics=METRIC_NAMES, images=files["candidates"], weight_inputs=weight_inputs))
    return folder


def build_viewer(results):
    root, paths, metrics_csv, cases = results
    case_dirs = []
    for scene, spp in cases:
        case_dir = case_folder(root, scene, spp, paths[(scene, spp)], weight_inputs={"ens": ["jbf", "oidn"]}) / "viewer_case"
        (case_dir / ".snakemake_timestamp").write_text("")      # what Snakemake leaves in a directory()
        case_dirs.append(str(case_dir))
    output = root / "viewer"
    manifest = viewer_step.write_viewer(metrics_csv, case_dirs, str(output), cases=cases, candidates=CANDIDATES,
                                  labels=LABELS, metric_names=METRIC_NAMES, static_dir=str(PAGE))
    return output, manifest


def loaded_manifest(folder) -> dict:
    text = (folder / "data.js").read_text()
    prefix = "window.MCBENCH_VIEWER = "
    assert text.startswith(prefix) and text.endswith(";\n")
    return json.loads(text[len(prefix):-2])


def test_viewer_folder_from_a_results_folder(results):
    output, manifest = build_viewer(results)
    for name in ("index.html", "viewer.js", "viewer.css", "data.js"):
        assert (output / name).is_file()
    data = loaded_manifest(output)
    assert data == json.loads(json.dumps(manifest))
    assert data["scenes"] == SCENES and data["spp"] == SPPS
    assert data["entries"] == ["reference", "noisy"] + CANDIDATES
    assert data["labels"]["reference"] == "Reference" and data["labels"]["ens"] == LABELS["ens"]
    assert data["metrics"] == METRIC_NAMES and data["exposures"] == list(viewer.EXPOSURES_EV)
    assert data["maps"] == ["relmse", "flip"] and set(data["scales"]) == {"relmse", "flip", "weights"}
    assert data["metric_labels"] == {"relmse": "relMSE", "flip": "HDR-FLIP"}
    assert data["lower_is_better"] == {"relmse": True, "flip": True}
    named = viewer.manifest_files(data)
    assert named and all((output / name).is_file() for name in named)
    on_disk = {str(p.relative_to(output)) for p in output.rglob("*") if p.is_file()}
    assert on_disk == set(named) | {"index.html", "viewer.js", "viewer.css", "data.js"}
    case = data["cases"]["room"]["16"]
    assert (case["width"], case["height"]) == (16, 16)
    assert case["numbers"]["jbf"] == {"relmse": 1000.0 * 3 + 10.0, "flip": 1000.0 * 3 + 11.0}
    assert "reference" not in case["numbers"] and "reference" not in case["errors"]
    assert [(w["input"], w["label"]) for w in case["weights"]["ens"]] == [("jbf", "JBF"), ("oidn", "OIDN")]
    assert "jbf" not in case["weights"]                            # a denoiser has no weight maps
    weight = viewer.index_values(palette_indices(output / case["weights"]["ens"][0]["file"]), viewer.WEIGHT_SCALE)
    np.testing.assert_allclose(weight, 0.3, atol=0.5 / viewer.LEVELS)
    # the ensemble equals the reference: no error; the noisy input has some
    relmse = viewer.index_values(palette_indices(output / case["errors"]["ens"]["relmse"]), viewer.RELMSE_SCALE)
    assert relmse.max() < 2 * viewer.RELMSE_SCALE.low
    noisy = viewer.index_values(palette_indices(output / case["errors"]["noisy"]["relmse"]), viewer.RELMSE_SCALE)
    assert np.median(noisy) > 1e-3
    # 4 cases of 16 x 16 with 4 entries: well under 1 MB
    assert viewer.directory_bytes(output) < 1_000_000
    # case images are hard links of the case folders' files (no second copy on disk)
    image = case["images"]["jbf"][next(iter(case["images"]["jbf"]))]
    source = results[0] / "cases" / "room" / "spp16" / "viewer_case" / Path(image).name
    assert (output / image).stat().st_ino == source.stat().st_ino


def test_assembling_again_replaces_stale_files_and_keeps_the_case_files(results):
    """Assembling into an existing viewer replaces a stale file by the case's image again (as a
    link), and the case folder's file keeps its bytes."""
    output, manifest = build_viewer(results)
    case = manifest["cases"]["room"]["16"]
    image = case["images"]["jbf"][next(iter(case["images"]["jbf"]))]
    source = results[0] / "cases" / "room" / "spp16" / "viewer_case" / Path(image).name
    before = source.read_bytes()
    (output / image).unlink()
    (output / image).write_bytes(b"edited in the viewer only")
    case_dirs = {("room", 16): str(source.parent)}
    viewer.assemble_viewer(output, static_dir=PAGE, case_dirs=case_dirs, manifest=manifest)
    assert source.read_bytes() == before and (output / image).read_bytes() == before
    assert (output / image).stat().st_ino == source.stat().st_ino


def test_viewer_refuses_a_case_record_of_another_case(results):
    root, paths, metrics_csv, cases = results
    case_dir = case_folder(root, "box", 4, paths[("box", 4)]) / "viewer_case"
    with pytest.raises(BenchError, match=r"case\.json: holds case \(box, 4\), expected \(box, 16\)"):
        viewer_step.write_viewer(metrics_csv, [str(case_dir)], str(root / "viewer"), cases=[("box", 16)],
                           candidates=CANDIDATES, labels=LABELS, metric_names=METRIC_NAMES, static_dir=str(PAGE))


def test_viewer_case_names_a_candidate_file_of_the_wrong_shape(results):
    root, paths, _, _ = results
    files = paths[("box", 4)]
    wrong = root / "wrong.exr"
    write_layers(wrong, {"color": np.zeros((8, 16, 3)), "color_a": np.zeros((8, 16, 3)), "color_b": np.zeros((8, 16, 3))})
    with pytest.raises(BenchError, match=re.escape(str(wrong))):
        case_folder(root, "box", 4, {**files, "candidates": {"jbf": str(wrong)}})


# --- the page: DOM contract, local files only -----------------------------------------------

class Elements(HTMLParser):
    def __init__(self):
        super().__init__()
        self.by_id, self.sources, self.options = {}, [], {}
        self._select = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.by_id[attrs["id"]] = (tag, attrs)
        if tag == "select":
            self._select = attrs.get("id")
            self.options[self._select] = []
        if tag == "option" and self._select:
            self.options[self._select].append(attrs.get("value"))
        for key in ("src", "href"):
            if key in attrs:
                self.sources.append(attrs[key])

    def handle_endtag(self, tag):
        if tag == "select":
            self._select = None


def test_page_has_the_dom_contract_and_loads_only_its_own_files():
    page = Elements()
    page.feed((PAGE / "index.html").read_text())
    expected = {"scene": "select", "spp": "select", "image-a": "select", "image-b": "select", "mode": "select",
                "exposure": "input", "flip": "button", "view-a": "img", "view-b": "img", "numbers": "div",
                "maps": "div"}
    for element_id, tag in expected.items():
        assert element_id in page.by_id, element_id
        assert page.by_id[element_id][0] == tag, element_id
    assert page.by_id["exposure"][1]["type"] == "range"
    assert page.options["mode"] == ["flip", "slide", "side"]
    local = [s for s in page.sources if not s.startswith("data:")]
    assert set(local) == {"viewer.css", "data.js", "viewer.js"}
    assert page.sources.index("data.js") < page.sources.index("viewer.js")
    script = (PAGE / "viewer.js").read_text() + (PAGE / "viewer.css").read_text()
    for forbidden in ("fetch(", "XMLHttpRequest", "http://", "https://", "import(", "@import"):
        assert forbidden not in script, forbidden
