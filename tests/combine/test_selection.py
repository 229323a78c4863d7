"""One-hot selection (Zheng et al. 2021 Sec. 5.2.6, Eq. 36-37) and naive averaging (Sec. 5.2.5):
mcbench.combine.selection, methods/one_hot.py and methods/naive_average.py against independent truth
(the equations written out per element, brute-force argmin loops, synthetic data with a known
best input)."""

from __future__ import annotations

import numpy as np
import pytest

from mcbench.combine import selection
from mcbench.filters.bilateral import cross_bilateral_filter
from mcbench.io.buffers import Denoised
from mcbench.filters.nlmeans import nl_means_filter
from methods import check_params, load_method

PREFILTERS = ("none", "sbf", "nfor", "post")


def random_inputs(buffers, n: int, seed: int) -> list[Denoised]:
    """``n`` inputs: each image plus independent uniform noise, float32."""
    rng = np.random.default_rng(seed)
    images = (buffers.color, buffers.color_a, buffers.color_b)
    return [Denoised(*(np.float32(x + rng.uniform(-0.2, 0.2, x.shape)) for x in images)) for _ in range(n)]


def brute_force_argmin(mse: np.ndarray) -> np.ndarray:
    """(H, W, C) index of the smallest value along axis 0, first one on ties, by explicit loops."""
    n, h, w, c = mse.shape
    best = np.zeros((h, w, c), dtype=int)
    for y in range(h):
        for x in range(w):
            for ch in range(c):
                for i in range(1, n):
                    if mse[i, y, x, ch] < mse[best[y, x, ch], y, x, ch]:
                        best[y, x, ch] = i
    return best


# --- the equations -------------------------------------------------------------------------------

def test_mse_maps_are_eq_36_37_written_out():
    rng = np.random.default_rng(0)
    n, h, w, c = 3, 2, 3, 3
    xa, xb = rng.uniform(0, 2, (2, h, w, c))
    va, vb = rng.uniform(0, 0.1, (2, h, w, c))
    ya, yb = rng.uniform(0, 2, (2, n, h, w, c))
    maps = selection.estimate_mse_maps(xa, xb, va, vb, ya, yb)
    for i in range(n):
        for y in range(h):
            for x in range(w):
                for ch in range(c):
                    p = (y, x, ch)
                    mse_a = (float(ya[i][p]) - float(xb[p])) ** 2 - float(vb[p])       # Eq. 36
                    mse_b = (float(yb[i][p]) - float(xa[p])) ** 2 - float(va[p])
                    var_y = (float(ya[i][p]) - float(yb[i][p])) ** 2 / 4                # Var[y_i]
                    assert maps["a"][i][p] == pytest.approx(mse_a, rel=1e-12, abs=1e-15)
                    assert maps["b"][i][p] == pytest.approx(mse_b, rel=1e-12, abs=1e-15)
                    assert maps["full"][i][p] == pytest.approx(0.5 * (mse_a + mse_b) - var_y,
                                                               rel=1e-12, abs=1e-15)   # Eq. 37


def test_full_buffer_mse_is_unbiased_on_gaussian_halves():
    """E[Eq. 37] = bias^2 + v/2 for independent halves with bias b and variance v each (the MSE
    of the mean of the halves), over many independent pixels."""
    rng = np.random.default_rng(1)
    shape = (1, 400, 400, 1)
    truth, bias, v, var_x = 1.0, 0.3, 0.04, 0.01
    xa, xb = truth + rng.normal(0, np.sqrt(var_x), (2,) + shape[1:])
    ya, yb = truth + bias + rng.normal(0, np.sqrt(v), (2,) + shape)
    maps = selection.estimate_mse_maps(xa, xb, np.full(shape[1:], var_x), np.full(shape[1:], var_x), ya, yb)
    assert maps["a"].mean() == pytest.approx(bias ** 2 + v, rel=0.03)
    assert maps["full"].mean() == pytest.approx(bias ** 2 + v / 2, rel=0.03)


def test_shape_mismatch_is_refused():
    with pytest.raises(ValueError, match="other_color"):
        selection.half_buffer_mse(np.zeros((2, 3, 4, 3)), np.zeros((3, 5, 3)), np.zeros((3, 5, 3)))
    with pytest.raises(ValueError, match=r"\(N, H, W, C\)"):
        selection.one_hot_selection(np.zeros((3, 4, 3)))


# --- selection --------------------------------------------------------------------------------

def test_one_hot_selection_equals_brute_force_argmin_with_ties():
    rng = np.random.default_rng(2)
    mse = rng.integers(0, 4, (4, 5, 6, 3)).astype(np.float64)   # few values: many ties
    one_hot = selection.one_hot_selection(mse)
    best = brute_force_argmin(mse)
    expected = np.stack([(best == i).astype(float) for i in range(4)])
    assert np.array_equal(one_hot, expected)
    assert np.array_equal(one_hot.sum(axis=0), np.ones((5, 6, 3)))


def test_ties_go_to_the_lowest_index():
    mse = np.zeros((3, 2, 2, 3))
    mse[0] = 1.0                                                   # inputs 1 and 2 tie below input 0
    one_hot = selection.one_hot_selection(mse)
    assert np.all(one_hot[1] == 1.0) and np.all(one_hot[0] == 0.0) and np.all(one_hot[2] == 0.0)
    assert np.all(selection.one_hot_selection(np.zeros((3, 2, 2, 3)))[0] == 1.0)


def test_selection_refuses_nan():
    mse = np.zeros((2, 2, 2, 3))
    mse[1, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="mse: 1"):
        selection.one_hot_selection(mse)


@pytest.mark.parametrize("variant", ["nl_means", "bilateral"])
def test_prefilters_filter_every_map_as_the_filter_alone_does(variant, make_render_buffers):
    """Stacking several (N, H, W, C) maps into one call changes nothing: each channel equals the
    core filter run on that channel alone."""
    buffers = make_render_buffers(height=9, width=8, seed=5)
    rng = np.random.default_rng(3)
    maps = [rng.normal(size=(2, 9, 8, 3)), rng.normal(size=(3, 9, 8, 3))]
    color, variance = buffers.color, buffers.variance
    if variant == "nl_means":
        filtered = selection.prefilter_mse_nl_means(maps, color, variance)

        def alone(channel):
            return nl_means_filter(channel, color, variance, **selection.NFOR_MSE_FILTER)
    else:
        filtered = selection.prefilter_mse_bilateral(maps, color, variance, buffers.albedo, buffers.normal)
        p = selection.SBF_MSE_FILTER

        def alone(channel):
            return cross_bilateral_filter(channel, color, variance, [buffers.albedo, buffers.normal],
                                          [p["sigma_albedo"], p["sigma_normal"]], p["sigma_spatial"],
                                          p["sigma_color"], p["radius"])[0]
    for original, result in zip(maps, filtered):
        assert result.shape == original.shape
        for i in range(original.shape[0]):
            for ch in range(3):
                np.testing.assert_allclose(result[i, :, :, ch], alone(original[i, :, :, ch]), rtol=1e-12, atol=1e-14)
        assert not np.allclose(result, original)                  # it did filter


def test_nfor_prefilter_constants_are_nfors():
    nfor = load_method("nfor")
    assert selection.NFOR_MSE_FILTER == dict(nfor.MSE_FILTER, alpha=nfor.NLM_ALPHA, epsilon=nfor.NLM_EPSILON)


def test_post_filter_keeps_the_simplex_and_a_uniform_selection(make_render_buffers):
    buffers = make_render_buffers(height=10, width=9, seed=6)
    inputs = random_inputs(buffers, 3, seed=7)
    y = {w: np.stack([d.image(w) for d in inputs]).astype(np.float64) for w in ("full", "a", "b")}
    rng = np.random.default_rng(8)
    one_hot = selection.one_hot_selection(rng.normal(size=(3, 10, 9, 3)))
    soft = selection.filter_selection_maps(one_hot, y["full"], y["a"], y["b"], buffers.albedo, buffers.normal)
    assert soft.min() >= 0.0 and soft.max() <= 1.0
    np.testing.assert_allclose(soft.sum(axis=0), 1.0, atol=1e-12)
    assert 0.0 < soft[0].mean() < 1.0 and not np.array_equal(soft, one_hot)
    uniform = np.zeros_like(one_hot)
    uniform[2] = 1.0
    np.testing.assert_allclose(selection.filter_selection_maps(uniform, y["full"], y["a"], y["b"],
                                                               buffers.albedo, buffers.normal), uniform, atol=1e-12)


def test_post_filter_and_blend_are_the_ensembles(make_render_buffers):
    """The selection's blend and "Post" filter are the ensemble's shared code (mcbench.combine:
    combine_with, the weight filter alone with the paper's parameters), and equal bit for bit
    what the selection computed on its own before: the guide z = sum s_i y_i, Var[z] ~
    (z^A - z^B)^2 / 2, one cross_bilateral_filter of the N x C maps as (K, H, W), clipped at 0
    and divided by the sum."""
    from mcbench.combine.blending import combine_with
    from mcbench.combine.weight_filter import FILTER_PARAMETERS, PAPER_FILTER, filter_weights

    assert selection.POST_FILTER == FILTER_PARAMETERS
    buffers = make_render_buffers(height=11, width=8, seed=12)
    inputs = random_inputs(buffers, 3, seed=13)
    y = {w: np.stack([d.image(w) for d in inputs]).astype(np.float64) for w in ("full", "a", "b")}
    s = selection.one_hot_selection(np.random.default_rng(14).normal(size=(3, 11, 8, 3)))
    assert np.array_equal(selection.blend(s, y["full"]), combine_with(s, y["full"]))
    soft = selection.filter_selection_maps(s, y["full"], y["a"], y["b"], buffers.albedo, buffers.normal)
    assert np.array_equal(soft, filter_weights(s, y["full"], y["a"], y["b"], buffers.albedo,
                                               buffers.normal, **PAPER_FILTER))
    n, h, w, c = s.shape
    guide = np.einsum("nhwc,nhwc->hwc", s, y["full"])
    variance = 0.5 * (np.einsum("nhwc,nhwc->hwc", s, y["a"]) - np.einsum("nhwc,nhwc->hwc", s, y["b"])) ** 2
    p = FILTER_PARAMETERS
    filtered = cross_bilateral_filter(np.moveaxis(s, 3, 1).reshape(n * c, h, w), guide, variance,
                                      [buffers.albedo, buffers.normal], [p["sigma_albedo"], p["sigma_normal"]],
                                      p["sigma_spatial"], p["sigma_color"], p["radius"], colour_distance="sum")
    clipped = np.maximum(np.moveaxis(filtered.reshape(n, c, h, w), 1, 3), 0.0)
    assert np.array_equal(soft, clipped / clipped.sum(axis=0, keepdims=True))


# --- the combiners --------------------------------------------------------------------------------

def test_naive_average_is_the_mean_of_each_image(make_render_buffers):
    buffers = make_render_buffers(height=6, width=5, seed=9)
    inputs = random_inputs(buffers, 3, seed=10)
    result = load_method("naive_average").combine(buffers, inputs)
    for which in ("full", "a", "b"):
        expected = (inputs[0].image(which).astype(np.float64) + inputs[1].image(which)
                    + inputs[2].image(which)) / 3
        np.testing.assert_allclose(result.image(which), expected, rtol=1e-6, atol=1e-7)
        assert result.image(which).dtype == np.float32


def test_naive_average_refuses_nan_and_no_inputs(make_render_buffers):
    module = load_method("naive_average")
    buffers = make_render_buffers(height=4, width=4, seed=11)
    inputs = random_inputs(buffers, 2, seed=12)
    inputs[1].b[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="inputs' b images: 1"):
        module.combine(buffers, inputs)
    with pytest.raises(ValueError, match="at least one input"):
        module.combine(buffers, [])


def test_unfiltered_one_hot_picks_each_images_argmin_by_hand(make_render_buffers):
    """prefilter="none": full from Eq. 37, A from A's Eq. 36 map, B from B's, per pixel-channel,
    written out per element; extras hold the full image's one-hot maps."""
    buffers = make_render_buffers(height=5, width=4, seed=13)
    inputs = random_inputs(buffers, 3, seed=14)
    result = load_method("one_hot").combine(buffers, inputs)
    f = lambda name: np.asarray(buffers.layers[name], np.float64)
    xa, xb, va, vb = f("color_a"), f("color_b"), f("variance_a"), f("variance_b")
    for y in range(5):
        for x in range(4):
            for ch in range(3):
                p = (y, x, ch)
                ya = [float(d.a[p]) for d in inputs]
                yb = [float(d.b[p]) for d in inputs]
                mse_a = [(v - xb[p]) ** 2 - vb[p] for v in ya]
                mse_b = [(v - xa[p]) ** 2 - va[p] for v in yb]
                mse = [0.5 * (a + b) - (u - v) ** 2 / 4 for a, b, u, v in zip(mse_a, mse_b, ya, yb)]
                best, best_a, best_b = (int(np.argmin(m)) for m in (mse, mse_a, mse_b))
                assert result.full[p] == inputs[best].full[p]
                assert result.a[p] == inputs[best_a].a[p]
                assert result.b[p] == inputs[best_b].b[p]
                for i in range(3):
                    assert result.extras[f"weights_filtered_{i}"][p] == float(i == best)
                    assert result.extras[f"weights_raw_{i}"][p] == float(i == best)


def test_identical_inputs_select_the_first(make_render_buffers):
    buffers = make_render_buffers(height=6, width=6, seed=15)
    first = random_inputs(buffers, 1, seed=16)[0]
    twin = Denoised(first.full.copy(), first.a.copy(), first.b.copy())
    for prefilter in PREFILTERS:
        result = load_method("one_hot").combine(buffers, [first, twin], prefilter=prefilter)
        assert np.all(result.extras["weights_filtered_0"] == 1.0), prefilter
        assert np.array_equal(result.full, first.full)


def fireflies(buffers):
    layers = {name: np.array(value, np.float32) for name, value in buffers.layers.items()}
    for (y, x), half in (((2, 3), "a"), ((7, 6), "b")):
        layers["color_" + half][y, x] *= 1e4
        layers["variance_" + half][y, x] = layers["color_" + half][y, x] ** 2
    layers["color"] = (layers["color_a"] + layers["color_b"]) / 2
    layers["variance"] = (layers["variance_a"] + layers["variance_b"]) / 4
    return type(buffers)(layers=layers, spp=buffers.spp)


def black_region(buffers):
    layers = {name: np.array(value, np.float32) for name, value in buffers.layers.items()}
    for value in layers.values():
        value[:, :4] = 0.0
    return type(buffers)(layers=layers, spp=buffers.spp)


@pytest.mark.parametrize("prefilter", PREFILTERS)
@pytest.mark.parametrize("case", ["fireflies", "black_region", "one_pixel"])
def test_variants_are_finite_deterministic_and_convex(prefilter, case, make_render_buffers):
    if case == "one_pixel":
        buffers = make_render_buffers(height=1, width=1, seed=17)
    else:
        buffers = make_render_buffers(height=10, width=8, seed=17)
        buffers = fireflies(buffers) if case == "fireflies" else black_region(buffers)
    inputs = random_inputs(buffers, 3, seed=18)
    if case == "black_region":
        for d in inputs:
            for image in (d.full, d.a, d.b):
                image[:, :4] = 0.0
    if case == "fireflies":
        inputs[1].a[5, 5] *= 1e4
    module = load_method("one_hot")
    first = module.combine(buffers, inputs, prefilter=prefilter)
    second = module.combine(buffers, inputs, prefilter=prefilter)
    stack = {w: np.stack([d.image(w) for d in inputs]) for w in ("full", "a", "b")}
    for which in ("full", "a", "b"):
        image = first.image(which)
        assert image.shape == buffers.shape + (3,) and np.isfinite(image).all()
        assert np.array_equal(image, second.image(which))
        # a convex combination of the inputs stays within their range
        assert np.all(image >= stack[which].min(axis=0) - 1e-3 * (1 + np.abs(image)))
        assert np.all(image <= stack[which].max(axis=0) + 1e-3 * (1 + np.abs(image)))
    weights = np.stack([first.extras[f"weights_filtered_{i}"] for i in range(3)]).astype(np.float64)
    assert weights.min() >= 0.0 and np.allclose(weights.sum(axis=0), 1.0, atol=1e-6)
    if prefilter != "post":
        assert set(np.unique(weights)) <= {0.0, 1.0}
    if case == "black_region" and prefilter == "none":   # all MSEs tie at 0 there: input 0
        # (a filter lets some of the lit side's MSE or selection in: its noisy pixels have
        # variance > 0, so their kernel weight to a black pixel is finite)
        assert np.all(weights[0][:, :4] == 1.0)


@pytest.mark.parametrize("prefilter", PREFILTERS)
def test_selection_finds_the_one_clearly_best_input(prefilter, make_render_buffers):
    """Known truth: input 0 is the truth plus small independent noise, inputs 1 and 2 the same
    plus a constant bias (+0.25, +0.3); the noisy halves have std 0.02. Selection must pick
    input 0 almost everywhere, in the full image and both halves, and so nearly reach its error,
    far below the naive average's."""
    buffers = make_render_buffers(height=24, width=20, half_std=0.02, seed=19)
    rng = np.random.default_rng(20)
    truth = make_render_buffers(height=24, width=20, half_std=0.0, seed=19).color.astype(np.float64)
    good = {w: truth + rng.normal(0, 0.01, truth.shape) for w in ("full", "a", "b")}
    inputs = [Denoised(*(np.float32(good[w] + bias) for w in ("full", "a", "b"))) for bias in (0.0, 0.25, 0.3)]
    result = load_method("one_hot").combine(buffers, inputs, prefilter=prefilter)
    weight_0 = result.extras["weights_filtered_0"]
    assert weight_0.mean() > 0.97, (prefilter, weight_0.mean())
    for which in ("full", "a", "b"):
        error = np.mean((result.image(which) - truth) ** 2)
        best = np.mean((inputs[0].image(which) - truth) ** 2)
        assert error < 1.5 * best, (prefilter, which, error, best)
        naive = np.mean((np.mean([d.image(which) for d in inputs], axis=0) - truth) ** 2)
        assert error < 0.2 * naive


def test_prefilter_is_a_checked_config_choice():
    module = load_method("one_hot")
    check_params(module, {"prefilter": "nfor"}, config_key="combiners[0].params")
    with pytest.raises(Exception, match=r"combiners\[0\].params.prefilter"):
        check_params(module, {"prefilter": "median"}, config_key="combiners[0].params")
    with pytest.raises(ValueError, match="unknown prefilter"):
        module.combine(None, [Denoised(np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), np.zeros((1, 1, 3)))],
                       prefilter="median")


@pytest.mark.parametrize("name", ["naive_average", "one_hot"])
def test_inputs_of_another_size_are_refused(name, make_render_buffers):
    buffers = make_render_buffers(height=6, width=5, seed=21)
    small = random_inputs(make_render_buffers(height=5, width=5, seed=21), 2, seed=22)
    with pytest.raises(ValueError, match="differ from the render's"):
        load_method(name).combine(buffers, small)
