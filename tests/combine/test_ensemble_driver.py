"""The ensemble's one pass in bands of rows (mcbench/combine/ensemble_driver.py) called directly:
the plugin's ``combine`` hands every option through unchanged, the solve blocks do not change the
numbers, and the input checks name what is wrong. The band-wise pass against the whole image, and
reading by rows, are tested through the plugin in tests/combine/test_ensemble.py."""

import inspect

import numpy as np
import pytest

from mcbench.combine.ensemble_driver import ensemble_in_bands
from mcbench.io.buffers import Denoised
from methods import ensemble as E


def scene(build, rng, h=13, w=9, n=3):
    """Noisy halves around a smooth image and n biased, noisy base outputs (float32)."""
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    truth = np.stack([0.5 + 0.4 * np.sin(3 * xx), 0.3 + 0.2 * yy, 0.2 + xx * yy], -1)
    buffers = build(truth, albedo=np.clip(truth, 0, 1), half_std=0.2, seed=rng)
    bias = rng.normal(0, 0.05, (n, 1, 1, 3))
    images = [truth + bias + rng.normal(0, 0.03, (n, h, w, 3)) for _ in range(3)]
    inputs = [Denoised(full=images[0][i].astype(np.float32), a=images[1][i].astype(np.float32),
                       b=images[2][i].astype(np.float32)) for i in range(n)]
    return buffers, inputs


def defaults():
    """The combiner's options at their defaults, from the plugin's signature."""
    return {name: p.default for name, p in inspect.signature(E.combine).parameters.items()
            if p.kind is inspect.Parameter.KEYWORD_ONLY}


def layers(result) -> dict:
    """Every array of a result: a Denoised, or the driver's (images, extras)."""
    if isinstance(result, Denoised):
        return result.layers()
    images, extras = result
    return {"color": images["full"], "color_a": images["a"], "color_b": images["b"], **extras}


def assert_same(x, y):
    x, y = layers(x), layers(y)
    assert x.keys() == y.keys() and len(x) > 3
    for name, layer in x.items():
        assert np.array_equal(layer, y[name]), name


@pytest.mark.parametrize("solver, weights", [("exact", "simplex"), ("iterative", "simplex"),
                                             ("exact", "unconstrained")])
def test_plugin_hands_every_option_through(solver, weights, make_render_buffers):
    """combine() with every other option off its default equals the driver called with the
    same options: an option dropped or routed to another parameter changes the numbers (the
    iterative solver is the one that uses the seed, start and stopping options)."""
    buffers, inputs = scene(make_render_buffers, np.random.default_rng(1))
    options = dict(solver=solver, seed=3, max_iterations=8, tolerance=3e-2, weights=weights,
                   channels="single", radius=3, sigma_spatial=2.5, sigma_color=0.7, sigma_albedo=0.2,
                   sigma_normal=0.3, guide_variance_blur="none", outlier_removal="neighbour_mean",
                   colour_distance="mean", filter_border="clip", normal_features="raw",
                   variance_sum_floor=1e-3, start="pair", away_steps=True)
    assert set(options) == set(defaults()) - {"filter"}
    assert {k for k, v in defaults().items() if options.get(k) == v} <= {"solver", "weights"}
    got = E.combine(buffers, inputs, **options)
    assert_same(got, ensemble_in_bands(buffers, inputs, block_pixels=E.BLOCK_PIXELS, filter=True, **options))
    # the comparison has power: the defaults give another result
    assert not np.array_equal(got.full, E.combine(buffers, inputs).full)


@pytest.mark.parametrize("filter_", [True, False])
def test_solve_blocks_do_not_change_the_numbers(filter_, make_render_buffers):
    """Blocks of 1, 2 (the last one short) and all rows give identical outputs."""
    buffers, inputs = scene(make_render_buffers, np.random.default_rng(2))
    options = dict(defaults(), filter=filter_)
    whole = ensemble_in_bands(buffers, inputs, block_pixels=10 ** 9, **options)
    for rows in (1, 2):
        assert_same(ensemble_in_bands(buffers, inputs, block_pixels=rows * 9, **options), whole)


def test_input_checks_name_the_problem(make_render_buffers):
    buffers, inputs = scene(make_render_buffers, np.random.default_rng(3))
    with pytest.raises(ValueError, match="at least one input"):
        ensemble_in_bands(buffers, [], block_pixels=E.BLOCK_PIXELS, **defaults())
    with pytest.raises(ValueError, match="variance_sum_floor"):
        ensemble_in_bands(buffers, inputs, block_pixels=E.BLOCK_PIXELS, **dict(defaults(), variance_sum_floor=-1.0))
    short = Denoised(full=inputs[1].full, a=inputs[1].a[:-1], b=inputs[1].b)
    with pytest.raises(ValueError, match="input 1 .* image a has shape"):
        ensemble_in_bands(buffers, [inputs[0], short], block_pixels=E.BLOCK_PIXELS, **defaults())
