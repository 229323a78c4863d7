"""Fast tests of the scene registry and mcbench.render (tiny images, low spp)."""

from __future__ import annotations

import numpy as np
import pytest

from mcbench import BenchError
from mcbench.buffers import ALL_LAYERS
from mcbench.render import (MAX_WAVEFRONT, decode_seed, merge_reference_chunks, mitsuba_seed,
                            passes_for, pick_variant, render_buffers, render_reference_chunk,
                            render_seed, scalar_seed_stride)
from scenes import UnknownSceneError, available_scenes, load_scene

TINY = (16, 16)
SCENES = ("cornell_box", "glass_caustics", "envmap_objects")


@pytest.fixture(scope="module")
def variant():
    return pick_variant("auto")


# ----------------------------------------------------------------------------- scenes

def test_registry_lists_the_scenes():
    assert set(SCENES) <= set(available_scenes())
    for name in SCENES:
        module = load_scene(name)
        assert module.DESCRIPTION and module.CATEGORY and len(module.RESOLUTION) == 2


def test_unknown_scene_names_the_config_key():
    with pytest.raises(UnknownSceneError, match="scenes") as info:
        load_scene("no_such_scene")
    assert "cornell_box" in str(info.value)
    with pytest.raises(BenchError, match="my.key"):
        load_scene("no_such_scene", config_key="my.key")


@pytest.mark.parametrize("scene", SCENES)
def test_every_scene_renders_finite_buffers(scene, variant):
    layers, meta = render_buffers(scene, 4, resolution=(24, 16))
    assert set(layers) == set(ALL_LAYERS)
    for name, array in layers.items():
        assert array.dtype == np.float32
        assert array.shape == ((16, 24) if name.startswith("depth") and "variance" not in name
                               or name.startswith("depth_variance") else (16, 24, 3)), name
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
    return render_buffers("cornell_box", 8, resolution=TINY, seed=0)


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
    again, _ = render_buffers("cornell_box", 8, resolution=TINY, seed=0)
    other, _ = render_buffers("cornell_box", 8, resolution=TINY, seed=1)
    for name in ALL_LAYERS:
        np.testing.assert_array_equal(layers[name], again[name])
    assert not np.array_equal(layers["color"], other["color"])


def test_bad_spp_is_refused():
    for spp in (0, 1, 3):
        with pytest.raises(BenchError, match="spp"):
            render_buffers("cornell_box", spp, resolution=TINY)


def test_stored_variance_matches_empirical_variance(variant):
    """Mean stored variance of the mean vs the variance across 16 independent half images."""
    halves, stored = [], []
    for seed in range(8):
        layers, _ = render_buffers("cornell_box", 16, resolution=TINY, seed=seed)
        halves += [layers["color_a"], layers["color_b"]]
        stored += [layers["variance_a"], layers["variance_b"]]
    empirical = np.var(np.stack(halves).astype(np.float64), axis=0, ddof=1)
    predicted = np.mean(np.stack(stored).astype(np.float64), axis=0)
    mask = predicted > 0
    assert mask.sum() > 0.5 * mask.size
    ratio = empirical[mask].mean() / predicted[mask].mean()
    assert 0.7 < ratio < 1.4, ratio


def test_spp2_gives_finite_nonnegative_half_variances(variant):
    layers, _ = render_buffers("cornell_box", 2, resolution=TINY)
    for name in ("variance", "variance_a", "variance_b"):
        assert np.all(np.isfinite(layers[name])) and layers[name].min() >= 0


def test_multi_pass_render_matches_its_pass_seeds(variant, monkeypatch):
    """Forcing several passes per half buffer still gives finite, sensible buffers."""
    if variant.startswith("scalar"):
        pytest.skip("scalar variants render in one pass")
    import mcbench.render as render
    monkeypatch.setattr(render, "MAX_WAVEFRONT", 16 * 16 * 3)   # 3 spp per pass
    layers, meta = render_buffers("cornell_box", 16, resolution=TINY, seed=2)
    assert meta["passes"] == "3" and len(meta["seeds_a"].split(",")) == 3
    assert np.all(np.isfinite(layers["color"])) and layers["variance"].min() >= 0


# ----------------------------------------------------------------------------- seeds

def test_seed_fields_round_trip():
    seed = render_seed("noisy", spp=4096, half=1, pass_index=7, base_seed=5)
    assert decode_seed(seed) == {"base_seed": 5, "kind": "noisy", "pass_index": 7, "spp": 4096, "half": 1}
    seed = render_seed("reference", chunk=255, pass_index=3, base_seed=7)
    assert decode_seed(seed) == {"base_seed": 7, "kind": "reference", "pass_index": 3, "chunk": 255}
    assert 0 <= seed < 2 ** 32


def _all_seeds(base_seed, width=128, height=128):
    """Every seed a benchmark at this resolution can use: even spp 2..2048 and multiples of
    2048 up to 65536, both halves, all passes; reference chunks 0..255 with up to 4096 spp."""
    levels = list(range(2, 2049, 2)) + list(range(4096, 65537, 2048))
    seeds = []
    for spp in levels:
        n_passes = len(passes_for(spp // 2, width, height, "llvm_ad_rgb"))
        seeds += [render_seed("noisy", spp=spp, half=h, pass_index=p, base_seed=base_seed)
                  for h in (0, 1) for p in range(n_passes)]
    n_passes = len(passes_for(4096, width, height, "llvm_ad_rgb"))
    seeds += [render_seed("reference", chunk=c, pass_index=p, base_seed=base_seed)
              for c in range(256) for p in range(n_passes)]
    return seeds


def test_seeds_never_overlap():
    everything = []
    for base_seed in range(8):
        seeds = _all_seeds(base_seed)
        assert len(set(seeds)) == len(seeds)
        everything += seeds
    assert len(set(everything)) == len(everything)
    assert all(0 <= s < 2 ** 32 for s in everything)
    # Pass indices are bounded by the spp and the wavefront cap: 65536 spp at 128x128.
    assert len(passes_for(32768, 128, 128, "llvm_ad_rgb")) == 32768 * 128 * 128 // MAX_WAVEFRONT


def test_scalar_pixel_seed_ranges_are_disjoint():
    """Scalar Mitsuba seeds pixels with mitsuba_seed * W*H + [0, blocks*B^2): intervals must not
    overlap for any two renders (one pass each) that the scheme allows."""
    width, height = 24, 16
    used = blocks = scalar_seed_stride(width, height) * width * height
    intervals = []
    for base_seed in range(8):
        for spp in (2, 4, 64, 2048, 65536):
            for half in (0, 1):
                s = render_seed("noisy", spp=spp, half=half, base_seed=base_seed)
                intervals.append(mitsuba_seed(s, "scalar_rgb", width, height) * width * height)
        for chunk in (0, 1, 255):
            s = render_seed("reference", chunk=chunk, base_seed=base_seed)
            intervals.append(mitsuba_seed(s, "scalar_rgb", width, height) * width * height)
    intervals.sort()
    assert all(b - a >= used for a, b in zip(intervals, intervals[1:]))
    assert intervals[-1] + blocks <= 2 ** 32
    with pytest.raises(BenchError, match="variant"):
        mitsuba_seed(render_seed("reference", chunk=0, base_seed=7), "scalar_rgb", 1024, 1024)


def test_bad_seed_arguments_are_refused():
    with pytest.raises(BenchError, match="seed"):
        render_seed("noisy", spp=4, half=0, base_seed=8)
    with pytest.raises(BenchError, match="spp"):
        render_seed("noisy", spp=3000, half=0)
    with pytest.raises(BenchError):
        render_seed("noisy", spp=4, half=0, pass_index=1 << 16)


# ----------------------------------------------------------------------------- references

def test_reference_chunks_render_and_merge(variant):
    chunks = [render_reference_chunk("cornell_box", spp, chunk, resolution=TINY)
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
    import mcbench.render as render

    real_pass = render._render_pass

    def pass_with_nan(*args, **kwargs):
        image = real_pass(*args, **kwargs)
        image[3, 5, :] = np.nan
        return image

    monkeypatch.setattr(render, "_render_pass", pass_with_nan)
    with pytest.raises(BenchError, match=r"cornell_box.*6 spp"):
        render_buffers("cornell_box", 6, resolution=TINY)


def test_thread_count_does_not_change_the_image(cornell_8spp):
    import drjit as dr

    before = dr.thread_count()
    try:
        layers, _ = render_buffers("cornell_box", 8, resolution=TINY, seed=0, threads=1)
        assert dr.thread_count() == 1
    finally:
        dr.set_thread_count(before)
    np.testing.assert_array_equal(layers["color"], cornell_8spp[0]["color"])
