"""Fast tests of the scene registry and mcbench.render.renderer (tiny images, low spp)."""

from __future__ import annotations

import types

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.io.buffers import ALL_LAYERS, BIN_LAYERS, RenderBuffers
from mcbench.render.renderer import (MAX_WAVEFRONT, film_size, forget_scene, load_scene_dict,
                            merge_reference_chunks, passes_for, render_buffers, render_dict_buffers,
                            render_reference_chunk, render_scene_sums)
from mcbench.render.seeds import (FIBRE_SEED_BASE, MAX_BASE_SEED, MAX_TRAINING_SEED, TRAINING_BASE_SEED,
                           decode_seed, decode_training_seed, mitsuba_seed, render_seed,
                           scalar_seed_stride, training_render_seed)
from mcbench.render.variants import pick_variant
from mcbench.contracts.scene import SceneSpec
from scenes import UnknownSceneError, available_scenes, load_scene, scene_spec

TINY = (16, 16)
SCENES = ("cornell_box", "glass_caustics", "envmap_objects")
CORNELL = load_scene("cornell_box")


@pytest.fixture(scope="module")
def variant():
    return pick_variant("auto")


# ----------------------------------------------------------------------------- scenes

def test_registry_lists_the_scenes():
    assert set(SCENES) <= set(available_scenes())
    for name in SCENES:
        spec = scene_spec(load_scene(name))
        assert spec.description and spec.category and len(spec.size) == 2


def test_unknown_scene_names_the_config_key():
    with pytest.raises(UnknownSceneError, match="scenes") as info:
        load_scene("no_such_scene")
    assert "cornell_box" in str(info.value)
    with pytest.raises(BenchError, match="my.key"):
        load_scene("no_such_scene", config_key="my.key")


@pytest.mark.parametrize("scene", SCENES)
def test_every_scene_renders_finite_buffers(scene, variant):
    layers, meta = render_buffers(load_scene(scene), 4, resolution=(24, 16))
    assert set(layers) == set(ALL_LAYERS) | set(BIN_LAYERS)
    for name, array in layers.items():
        assert array.dtype == np.float32
        assert array.shape == ((16, 24) if name.startswith(("depth", "visibility")) else (16, 24, 3)), name
        assert np.all(np.isfinite(array)), name
    assert layers["color"].mean() > 0
    for name in ALL_LAYERS:
        if "variance" in name:
            assert layers[name].min() >= 0, name
    assert meta["scene"] == scene and meta["spp"] == "4" and meta["variant"] == variant
    assert meta["resolution"] == "24x16"


# ----------------------------------------------------------------------------- buffers

@pytest.fixture(scope="module")
def cornell_8spp(variant):
    return render_buffers(CORNELL, 8, resolution=TINY, seed=0)


def test_full_is_mean_of_halves_and_halves_differ(cornell_8spp):
    layers, meta = cornell_8spp
    for q in ("color", "albedo", "normal", "depth"):
        np.testing.assert_array_equal(layers[q], (layers[q + "_a"] + layers[q + "_b"]) / np.float32(2))
    assert not np.array_equal(layers["color_a"], layers["color_b"])
    assert set(meta["seeds_a"].split(",")).isdisjoint(meta["seeds_b"].split(","))


def test_full_variance_is_pooled_and_about_half_the_halves(cornell_8spp):
    layers, _ = cornell_8spp
    ratio = layers["variance"].mean() / (0.5 * (layers["variance_a"] + layers["variance_b"]).mean() / 2)
    assert 0.6 < ratio < 1.6


def test_same_seed_same_image_other_seed_other_image(cornell_8spp):
    layers, _ = cornell_8spp
    again, _ = render_buffers(CORNELL, 8, resolution=TINY, seed=0)
    other, _ = render_buffers(CORNELL, 8, resolution=TINY, seed=1)
    for name in ALL_LAYERS:
        np.testing.assert_array_equal(layers[name], again[name])
    assert not np.array_equal(layers["color"], other["color"])


def test_sample_bins_make_the_half_buffers(cornell_8spp):
    """Four quarter-sample bins: A = mean of bins 0-1 and B = mean of bins 2-3 exactly, bins
    differ, their seeds are disjoint, and a bin's variance of the mean (2 samples) is about twice
    its half buffer's (4 samples)."""
    layers, meta = cornell_8spp
    np.testing.assert_array_equal(layers["color_a"], (layers["color_bin0"] + layers["color_bin1"]) / np.float32(2))
    np.testing.assert_array_equal(layers["color_b"], (layers["color_bin2"] + layers["color_bin3"]) / np.float32(2))
    assert not np.array_equal(layers["color_bin0"], layers["color_bin1"])
    ratio = (layers["variance_bin0"] + layers["variance_bin1"]).mean() / (2 * layers["variance_a"].mean())
    assert 1.2 < ratio < 3.2
    seeds = meta["seeds_a"].split(",") + meta["seeds_b"].split(",")
    assert len(seeds) == len(set(seeds)) == 4
    buffers = RenderBuffers(layers=layers, spp=8)
    (c0, v0), (c1, v1) = buffers.sub_images("a")
    assert c0 is layers["color_bin0"] and v1 is layers["variance_bin1"]
    (c0, _), (c1, _) = buffers.sub_images("full")
    assert c0 is layers["color_a"] and c1 is layers["color_b"]


def test_one_sample_bins_take_the_pair_variance(variant):
    """At 4 spp each bin holds one sample: its variance is (b0 - b1)^2 / 2 within its half."""
    layers, _ = render_buffers(CORNELL, 4, resolution=TINY, seed=2)
    for first, second in ((0, 1), (2, 3)):
        expected = 0.5 * (layers[f"color_bin{first}"].astype(np.float64) - layers[f"color_bin{second}"]) ** 2
        for j in (first, second):
            np.testing.assert_allclose(layers[f"variance_bin{j}"], expected, rtol=1e-5, atol=1e-7)


def test_spp_not_a_multiple_of_four_has_no_bins(variant):
    layers, _ = render_buffers(CORNELL, 6, resolution=TINY)
    assert set(layers) == set(ALL_LAYERS)
    buffers = RenderBuffers(layers=layers, spp=6, source="x.exr")
    assert not buffers.has_sub_buffers()
    with pytest.raises(BenchError, match=r"x\.exr.*bins"):
        buffers.sub_images("a")
    assert buffers.sub_images("full")[0][0] is layers["color_a"]


def test_bad_spp_is_refused():
    for spp in (0, 1, 3):
        with pytest.raises(BenchError, match="spp"):
            render_buffers(CORNELL, spp, resolution=TINY)


def test_stored_variance_matches_empirical_variance(variant):
    """Mean stored variance of the mean vs the variance across 14 independent half images."""
    halves, stored = [], []
    for seed in range(MAX_BASE_SEED + 1):
        layers, _ = render_buffers(CORNELL, 16, resolution=TINY, seed=seed)
        halves += [layers["color_a"], layers["color_b"]]
        stored += [layers["variance_a"], layers["variance_b"]]
    empirical = np.var(np.stack(halves).astype(np.float64), axis=0, ddof=1)
    predicted = np.mean(np.stack(stored).astype(np.float64), axis=0)
    mask = predicted > 0
    assert mask.sum() > 0.5 * mask.size
    ratio = empirical[mask].mean() / predicted[mask].mean()
    assert 0.7 < ratio < 1.4, ratio


def test_spp2_gives_finite_nonnegative_half_variances(variant):
    layers, _ = render_buffers(CORNELL, 2, resolution=TINY)
    for name in ("variance", "variance_a", "variance_b"):
        assert np.all(np.isfinite(layers[name])) and layers[name].min() >= 0


def test_multi_pass_render_matches_its_pass_seeds(variant, monkeypatch):
    """Forcing several passes per half buffer still gives finite, sensible buffers."""
    if variant.startswith("scalar"):
        pytest.skip("scalar variants render in one pass")
    import mcbench.render.renderer as render
    monkeypatch.setattr(render, "MAX_WAVEFRONT", 16 * 16 * 3)   # 3 spp per pass
    layers, meta = render_buffers(CORNELL, 16, resolution=TINY, seed=2)
    # each half: two bins of 4 spp, each in passes of 3 + 1 spp
    assert meta["passes"] == "4" and len(meta["seeds_a"].split(",")) == 4
    assert np.all(np.isfinite(layers["color"])) and layers["variance"].min() >= 0


# ----------------------------------------------------------------------------- scene dicts

def test_dict_render_equals_module_render_bit_for_bit(variant):
    """The public scene-dict path reproduces render_buffers exactly, given the same seeds."""
    layers, meta = render_buffers(CORNELL, 4, resolution=(8, 8), seed=3)
    desc = CORNELL.build(8, 8)
    try:
        again, seeds = render_dict_buffers(
            desc, 4, lambda half, j, p: render_seed("noisy", spp=4, half=half, bin=j, pass_index=p, base_seed=3),
            key="test-dict-cornell")
    finally:
        forget_scene("test-dict-cornell")
    assert seeds == [int(s) for s in meta["seeds_a"].split(",") + meta["seeds_b"].split(",")]
    for name in ALL_LAYERS + BIN_LAYERS:
        assert again[name].dtype == layers[name].dtype
        np.testing.assert_array_equal(again[name], layers[name], err_msg=name)


def test_scene_sums_equal_a_reference_chunk(variant):
    """render_scene_sums with a chunk's seeds gives that chunk's sample means, S1 / spp: the chunk's
    colour pass (no first-hit AOVs) draws the same samples, summed by a film of fewer channels
    (float32 rounding of the sums' order, a few ulp), and its one feature pass, seeded as its first
    colour pass, traces the same camera rays (the same first-hit depth, to float32 rounding)."""
    chunk, meta = render_reference_chunk(CORNELL, 6, 2, resolution=(8, 8))
    try:
        sums, seeds = render_scene_sums(CORNELL.build(8, 8), 6,
                                        lambda p: render_seed("reference", chunk=2, pass_index=p),
                                        key="test-sums-cornell")
    finally:
        forget_scene("test-sums-cornell")
    assert ",".join(map(str, seeds)) == meta["seeds"]
    assert sums["color"][0].dtype == np.float64 and sums["depth"][0].shape == (8, 8, 1)
    np.testing.assert_allclose(chunk["color"], (sums["color"][0] / 6).astype(np.float32), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(chunk["color_m2"], (sums["color"][1] / 6).astype(np.float32), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(chunk["depth"], (sums["depth"][0][..., 0] / 6).astype(np.float32), rtol=1e-6)


def test_load_scene_dict_caches_by_key_leaves_the_dict_alone_and_forgets(variant):
    desc = CORNELL.build(8, 6)
    integrator, film = desc["integrator"], dict(desc["sensor"]["film"])
    assert film_size(desc) == (8, 6)
    try:
        scene, own = load_scene_dict(desc, key="test-cache")
        assert own == integrator and desc["integrator"] is integrator and desc["sensor"]["film"] == film
        assert load_scene_dict(desc, key="test-cache")[0] is scene           # cached
        sensor = scene.sensors()[0]                                          # wrapped for rendering
        assert "m2_nested.integrator.R" in str(scene.integrator()) and "nested.dd.T" in str(scene.integrator())
        assert str(sensor.film().rfilter()).startswith("BoxFilter") and sensor.sampler().sample_count() == 1
        forget_scene("test-cache")
        assert load_scene_dict(desc, key="test-cache")[0] is not scene       # loaded again
    finally:
        forget_scene("test-cache")


def test_a_film_of_the_wrong_size_names_the_scene(variant):
    wrong = types.ModuleType("scenes.wrong_size")
    wrong.SCENE = SceneSpec(description="a film one pixel too wide", category="test", resolution=(8, 8),
                            build=lambda width, height: scene_spec(CORNELL).build(width + 1, height))
    with pytest.raises(BenchError, match=r"wrong_size.*build\(8, 8\) made a 9x8 film"):
        render_buffers(wrong, 2)


# ----------------------------------------------------------------------------- seeds

def test_seed_fields_round_trip():
    seed = render_seed("noisy", spp=4096, half=1, bin=1, pass_index=7, base_seed=5)
    assert decode_seed(seed) == {"base_seed": 5, "kind": "noisy", "pass_index": 7, "spp": 4096, "half": 1,
                                 "bin": 1}
    seed = render_seed("reference", chunk=255, pass_index=3, base_seed=6)
    assert decode_seed(seed) == {"base_seed": 6, "kind": "reference", "pass_index": 3, "chunk": 255}
    assert 0 <= seed < 2 ** 32


def _all_seeds(base_seed, width=128, height=128):
    """Every seed a benchmark at this resolution can use: even spp 2..2048 and multiples of
    2048 up to 65536, both halves, all passes; reference chunks 0..255 with up to 4096 spp."""
    levels = list(range(2, 2049, 2)) + list(range(4096, 65537, 2048))
    seeds = []
    for spp in levels:
        bins = (0, 1) if spp % 4 == 0 else (0,)
        n_passes = len(passes_for(spp // 2 // len(bins), width, height, "llvm_ad_rgb"))
        seeds += [render_seed("noisy", spp=spp, half=h, bin=j, pass_index=p, base_seed=base_seed)
                  for h in (0, 1) for j in bins for p in range(n_passes)]
    n_passes = len(passes_for(4096, width, height, "llvm_ad_rgb"))
    seeds += [render_seed("reference", chunk=c, pass_index=p, base_seed=base_seed)
              for c in range(256) for p in range(n_passes)]
    return seeds


def test_seeds_never_overlap():
    everything = []
    for base_seed in range(MAX_BASE_SEED + 1):
        seeds = _all_seeds(base_seed)
        assert len(set(seeds)) == len(seeds)
        everything += seeds
    assert len(set(everything)) == len(everything)
    assert all(0 <= s < 2 ** 32 for s in everything)
    # Pass indices are bounded by the spp and the wavefront cap: 65536 spp at 128x128.
    assert len(passes_for(32768, 128, 128, "llvm_ad_rgb")) == 32768 * 128 * 128 // MAX_WAVEFRONT


def _random_render_seeds(rng, n):
    """``n`` seeds of render_seed drawn uniformly over every field it accepts."""
    codes = rng.integers(0, 2047, n)                    # spp codes 0..1023 and 1025..2047
    spps = np.where(codes < 1024, 2 * (codes + 1), 2048 * np.maximum(codes - 1023, 1))
    out = []
    for base, kind, spp, half, chunk, p, j in zip(rng.integers(0, MAX_BASE_SEED + 1, n),
                                                 rng.integers(0, 2, n), spps, rng.integers(0, 2, n),
                                                 rng.integers(0, 4096, n), rng.integers(0, 1 << 15, n),
                                                 rng.integers(0, 2, n)):
        out.append(render_seed("noisy", spp=int(spp), half=int(half), bin=int(j), pass_index=int(p),
                               base_seed=int(base))
                   if kind == 0 else
                   render_seed("reference", chunk=int(chunk), pass_index=int(p), base_seed=int(base)))
    return out


def _random_training_seeds(rng, n):
    """``n`` seeds of training_render_seed drawn uniformly over every field it accepts."""
    out = []
    for scene, kind, log_spp, half, p, j in zip(rng.integers(0, MAX_TRAINING_SEED + 1, n),
                                               rng.integers(0, 2, n), rng.integers(1, 16, n),
                                               rng.integers(0, 2, n), rng.integers(0, 4096, n),
                                               rng.integers(0, 2, n)):
        out.append(training_render_seed(int(scene), "noisy", 1 << int(log_spp), int(half), int(p) % 64, bin=int(j))
                   if kind == 0 else training_render_seed(int(scene), "target", pass_index=int(p)))
    return out


def test_both_seed_layouts_decode_back():
    rng = np.random.default_rng(11)
    for seed in _random_render_seeds(rng, 3000):
        fields = decode_seed(seed)
        kind = fields.pop("kind")
        assert 0 <= seed < 2 ** 32 and render_seed(kind, **fields) == seed
    for seed in _random_training_seeds(rng, 3000):
        fields = decode_training_seed(seed)
        assert 0 <= seed < 2 ** 32 and training_render_seed(fields.pop("scene_seed"), fields.pop("kind"),
                                                           **fields) == seed
    assert decode_training_seed(training_render_seed(FIBRE_SEED_BASE + 5, "noisy", 32768, 1, 63, bin=1)) == {
        "scene_seed": FIBRE_SEED_BASE + 5, "kind": "noisy", "spp": 32768, "half": 1, "bin": 1, "pass_index": 63}


def test_no_training_seed_is_a_render_seed():
    """Brute force over a uniform sample of both layouts' full ranges, then the structural
    argument: render seeds have top bits (base seed) 0..6 at every field extreme, training
    seeds 7, and render_seed refuses base seed 7."""
    rng = np.random.default_rng(12)
    render = set(_random_render_seeds(rng, 20000))
    training = set(_random_training_seeds(rng, 20000))
    assert len(render) > 19000 and len(training) > 19000
    assert not render & training
    assert {s >> 29 for s in render} == set(range(MAX_BASE_SEED + 1))
    assert {s >> 29 for s in training} == {TRAINING_BASE_SEED}
    extremes = [render_seed("noisy", spp=spp, half=h, bin=j, pass_index=p, base_seed=b)
                for spp in (2, 2048, 4096, 2048 * 1024) for h in (0, 1) for j in (0, 1) for p in (0, 32767)
                for b in (0, MAX_BASE_SEED)]
    extremes += [render_seed("reference", chunk=c, pass_index=p, base_seed=b)
                 for c in (0, 4095) for p in (0, 32767) for b in (0, MAX_BASE_SEED)]
    assert max(extremes) < TRAINING_BASE_SEED << 29
    assert min(training_render_seed(0, "noisy", 2, 0, 0), training_render_seed(0, "target")) \
        >= TRAINING_BASE_SEED << 29
    assert training_render_seed(MAX_TRAINING_SEED, "target", pass_index=4095) == 2 ** 32 - 1
    with pytest.raises(BenchError, match="reserved for training"):
        render_seed("noisy", spp=4, half=0, base_seed=TRAINING_BASE_SEED)


def test_scalar_pixel_seed_ranges_are_disjoint():
    """Scalar Mitsuba seeds pixels with mitsuba_seed * W*H + [0, blocks*B^2): intervals must not
    overlap for any two renders (one pass each) that the scheme allows."""
    width, height = 24, 16
    used = blocks = scalar_seed_stride(width, height) * width * height
    intervals = []
    for base_seed in range(MAX_BASE_SEED + 1):
        for spp in (2, 4, 64, 2048, 65536):
            for half in (0, 1):
                for j in ((0, 1) if spp % 4 == 0 else (0,)):
                    s = render_seed("noisy", spp=spp, half=half, bin=j, base_seed=base_seed)
                    intervals.append(mitsuba_seed(s, "scalar_rgb", width, height) * width * height)
        for chunk in (0, 1, 255):
            s = render_seed("reference", chunk=chunk, base_seed=base_seed)
            intervals.append(mitsuba_seed(s, "scalar_rgb", width, height) * width * height)
    intervals.sort()
    assert all(b - a >= used for a, b in zip(intervals, intervals[1:]))
    assert intervals[-1] + blocks <= 2 ** 32
    with pytest.raises(BenchError, match="variant"):
        mitsuba_seed(render_seed("reference", chunk=0, base_seed=6), "scalar_rgb", 1024, 1024)


def test_bad_seed_arguments_are_refused():
    with pytest.raises(BenchError, match="seed"):
        render_seed("noisy", spp=4, half=0, base_seed=8)
    with pytest.raises(BenchError, match="reserved for training"):
        render_seed("reference", chunk=0, base_seed=TRAINING_BASE_SEED)
    with pytest.raises(BenchError, match="spp"):
        render_seed("noisy", spp=3000, half=0)
    with pytest.raises(BenchError):
        render_seed("noisy", spp=4, half=0, pass_index=1 << 15)
    with pytest.raises(ValueError, match="bin"):
        render_seed("reference", chunk=0, bin=1)
    with pytest.raises(BenchError):
        training_render_seed(0, "noisy", 4, 0, pass_index=64)


# ----------------------------------------------------------------------------- references

def test_reference_chunks_render_and_merge(variant):
    chunks = [render_reference_chunk(CORNELL, spp, chunk, resolution=TINY)
              for chunk, spp in ((0, 4), (1, 8))]
    for layers, meta in chunks:
        assert set(layers) == {"color", "color_m2", "albedo", "normal", "depth"}
        assert layers["depth"].shape == (16, 16)
        assert np.all(layers["color_m2"] >= layers["color"] ** 2 * (1 - 1e-5) - 1e-7)
    assert chunks[0][1]["seeds"] != chunks[1][1]["seeds"]
    merged, meta = merge_reference_chunks(chunks)
    assert meta["spp"] == "12" and meta["chunks"] == "2"
    assert np.all(np.isfinite(merged["color"])) and merged["variance"].min() >= 0
    with pytest.raises(BenchError, match="share seed"):
        merge_reference_chunks([chunks[0], chunks[0]])


def test_merge_is_the_spp_weighted_closed_form():
    rng = np.random.default_rng(0)
    n1, n2 = 4, 12
    samples1 = rng.gamma(2.0, 1.0, size=(n1, 5, 6, 3))
    samples2 = rng.gamma(2.0, 1.0, size=(n2, 5, 6, 3))

    def chunk(samples, index):
        layers = {"color": samples.mean(0), "color_m2": (samples ** 2).mean(0),
                  "albedo": np.full((5, 6, 3), 0.5), "normal": np.zeros((5, 6, 3)),
                  "depth": np.full((5, 6), float(index))}
        meta = {"scene": "s", "spp": str(len(samples)), "chunk": str(index), "variant": "v",
                "resolution": "6x5", "seeds": str(index)}
        return layers, meta

    merged, meta = merge_reference_chunks([chunk(samples1, 0), chunk(samples2, 1)])
    everything = np.concatenate([samples1, samples2])
    np.testing.assert_allclose(merged["color"], everything.mean(0), rtol=1e-6)
    np.testing.assert_allclose(merged["variance"], everything.var(0, ddof=1) / (n1 + n2), rtol=1e-5)
    np.testing.assert_allclose(merged["depth"], (0 * n1 + 1 * n2) / (n1 + n2), rtol=1e-6)
    assert meta["spp"] == str(n1 + n2)

    other = chunk(samples2, 2)
    other[1]["resolution"] = "7x5"
    with pytest.raises(BenchError, match="resolution"):
        merge_reference_chunks([chunk(samples1, 0), other])


def test_nan_from_mitsuba_raises_naming_scene_and_spp(variant, monkeypatch):
    import mcbench.render.renderer as render

    real_pass = render._render_pass

    def pass_with_nan(*args, **kwargs):
        image = real_pass(*args, **kwargs)
        image[3, 5, :] = np.nan
        return image

    monkeypatch.setattr(render, "_render_pass", pass_with_nan)
    with pytest.raises(BenchError, match=r"cornell_box.*6 spp"):
        render_buffers(CORNELL, 6, resolution=TINY)


def test_thread_count_does_not_change_the_image(cornell_8spp):
    import drjit as dr

    before = dr.thread_count()
    try:
        layers, _ = render_buffers(CORNELL, 8, resolution=TINY, seed=0, threads=1)
        assert dr.thread_count() == 1
    finally:
        dr.set_thread_count(before)
    np.testing.assert_array_equal(layers["color"], cornell_8spp[0]["color"])


def test_a_reference_chunk_prints_its_passes_with_elapsed_time_and_eta(variant, monkeypatch, capsys):
    """Progress of a reference chunk: one line per pass (to stdout, which run_logged sends to
    the job log), passes and samples counted up, the last pass with nothing left (eta 0)."""
    import re

    import mcbench.render.renderer as render

    monkeypatch.setattr(render, "MAX_WAVEFRONT", 8 * 8 * 2)     # 2 spp per pass at 8x8
    expected = passes_for(7, 8, 8, variant)
    assert len(expected) == (1 if variant.startswith("scalar") else 4)
    capsys.readouterr()
    render_reference_chunk(CORNELL, 7, 3, resolution=(8, 8), variant=variant)
    lines = [line for line in capsys.readouterr().out.splitlines() if "pass" in line]
    assert len(lines) == len(expected)
    pattern = (r"reference cornell_box chunk 3 \(8x8, [a-z_]+\): pass (\d+)/(\d+) \((\d+)/7 spp\), "
               r"elapsed (\d+\.\d) s, eta (\d+\.\d|unknown)( s)?")
    parsed = [re.fullmatch(pattern, line) for line in lines]
    assert all(parsed), lines
    assert [int(m.group(1)) for m in parsed] == list(range(1, len(expected) + 1))
    assert {int(m.group(2)) for m in parsed} == {len(expected)}
    assert [int(m.group(3)) for m in parsed] == list(np.cumsum(expected))
    assert parsed[-1].group(5) == "0.0"
    elapsed = [float(m.group(4)) for m in parsed]
    assert elapsed == sorted(elapsed)


def test_progress_eta_and_stage_lines(capsys):
    from mcbench.progress import LARGE_IMAGE_PIXELS, StageLog, eta_seconds, progress_line

    assert eta_seconds(10.0, 2, 8) == 30.0          # 5 s per unit, 6 units left
    assert eta_seconds(10.0, 8, 8) == 0.0 and eta_seconds(0.0, 0, 8) == float("inf")
    assert progress_line("job", "step 2/8", 10.0, 30.0) == "job: step 2/8, elapsed 10.0 s, eta 30.0 s"
    assert progress_line("job", "step 0/8", 0.0, float("inf")).endswith("eta unknown")
    ticks = iter([100.0, 101.5, 104.25])
    log = StageLog("nfor", clock=lambda: next(ticks))
    log("prefilter")
    log("regression")
    assert capsys.readouterr().out.splitlines() == ["nfor: prefilter done, elapsed 1.5 s",
                                                    "nfor: regression done, elapsed 4.2 s"]
    side = int(LARGE_IMAGE_PIXELS ** 0.5)
    StageLog.for_image("rdfc", side, side)("quiet")            # exactly 256 x 256: quiet
    assert capsys.readouterr().out == ""
    StageLog.for_image("rdfc", side, side + 1)("loud")
    assert capsys.readouterr().out.startswith(f"rdfc ({side + 1}x{side}): loud done, elapsed ")
