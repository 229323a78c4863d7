"""HDR-FLIP of mcbench.analysis.hdr_flip against NVIDIA's flip-evaluator (the installed wheel,
called here as the independent truth), and its reuse of the reference's side."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from mcbench.analysis import hdr_flip
from mcbench.analysis.metrics import flip, flip_exposure_range, flip_map, flip_with_map

# Pairs without regions where the image equals the reference: the package's float32 rounding
# stays near 1e-6 there (measured max 2.3e-6 per pixel, 1e-6 relative in the mean).
MAP_TOLERANCE = 1e-5
MEAN_TOLERANCE = 5e-6


def package_flip(image, reference, **parameters):
    import flip_evaluator

    error_map, mean, used = flip_evaluator.evaluate(np.float32(reference), np.float32(image), "HDR",
                                                    applyMagma=False, parameters=parameters)
    return np.asarray(error_map, dtype=np.float64).reshape(image.shape[:2]), float(mean), used


def generic_pairs():
    """(name, image, reference): HDR radiance with a long bright tail, and images that differ from
    it everywhere (noise, blur, a tint), at odd, small and non-square sizes (clamped borders)."""
    rng = np.random.default_rng(5)
    for shape in [(24, 20, 3), (7, 9, 3), (3, 40, 3), (48, 33, 3)]:
        reference = rng.gamma(1.0, 1.0, size=shape)
        yield f"noise{shape}", np.maximum(reference + rng.normal(0, 0.2, size=shape), 0.0), reference
        yield f"blur{shape}", gaussian_filter(reference, (1.0, 1.0, 0.0)), reference
        yield f"tint{shape}", reference * np.array([1.1, 0.95, 0.9]), reference


def test_flip_equals_the_package_within_its_float32_rounding():
    for name, image, reference in generic_pairs():
        expected_map, expected_mean, _ = package_flip(image, reference)
        values, mean = flip_with_map(image, reference)
        assert values.shape == image.shape[:2] and values.dtype == np.float64
        assert np.abs(values - expected_map).max() <= MAP_TOLERANCE, name
        assert mean == pytest.approx(expected_mean, rel=MEAN_TOLERANCE), name
        assert mean == np.mean(values) and flip(image, reference) == mean
        np.testing.assert_array_equal(flip_map(image, reference), values)


def test_where_the_image_equals_the_reference_the_package_adds_its_rounding():
    """A step edge moved by one pixel: the flat regions are equal in both images. HyAB's 0.7 power
    and the feature's 0.5 power turn the package's float32 rounding there into errors up to ~3e-4;
    in float64 they stay below 1e-6, so the differences are one-sided (the package higher)."""
    edge = np.full((16, 64, 3), 0.05)
    edge[:, 32:] = 4.05
    image = np.full_like(edge, 0.05)
    image[:, 33:] = 4.05
    expected_map, _, _ = package_flip(image, edge)
    values = flip_map(image, edge)
    flat = np.abs(np.arange(64) - 32.5) > 11         # columns beyond the filters' reach of the edges (radius 10)
    assert np.all(values[:, flat] < 1e-6)
    assert np.all(expected_map[:, flat] >= values[:, flat])
    assert np.abs(values - expected_map).max() < 5e-4


@pytest.mark.parametrize("constant, value", [
    ("_QC", 0.71), ("_QF", 0.51), ("_PC", 0.41), ("_PT", 0.96), ("_W", 0.083),
    ("_A1", (1.0, 1.0, 34.0)), ("_B1", (0.0048, 0.0053, 0.04)), ("_B2", (1.0e-5, 1.0e-5, 0.026)),
    ("ACES", (0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.141)),
    ("_INV_ILLUMINANT", np.array([1.0, 1.0, 0.918357670])), ("PIXELS_PER_DEGREE", 66.0),
])
def test_a_wrong_constant_fails_the_package_comparison(monkeypatch, constant, value):
    """Each of FLIP's constants, changed a little, moves the map beyond the tolerance the
    comparison above allows: that comparison can fail."""
    _, image, reference = next(generic_pairs())
    expected_map, _, _ = package_flip(image, reference)
    monkeypatch.setattr(hdr_flip, constant, value)
    for cached in (hdr_flip._spatial_filters, hdr_flip._feature_filters, hdr_flip._colour_distance_bounds):
        cached.cache_clear()
    try:
        start, stop = flip_exposure_range(reference)
        ppd = hdr_flip.PIXELS_PER_DEGREE
        prepared = hdr_flip.prepare_flip_reference(reference, start=start, stop=stop, ppd=ppd)
        values = hdr_flip.hdr_flip_map(image, prepared, ppd=ppd)
    finally:
        monkeypatch.undo()
        for cached in (hdr_flip._spatial_filters, hdr_flip._feature_filters, hdr_flip._colour_distance_bounds):
            cached.cache_clear()
    assert np.abs(values - expected_map).max() > MAP_TOLERANCE


def test_exposure_levels_are_the_packages():
    """Count and levels of the exposures equal those the package reports using, its range given
    (a range just above and at a whole number of stops: the count's ceil in float32)."""
    _, image, reference = next(generic_pairs())
    for start, stop in [(-1.25, 4.5), (0.5, 3.5), (2.0, 2.0), (-3.0, 20.0000001)]:
        _, _, used = package_flip(image, reference, startExposure=start, stopExposure=stop)
        levels = hdr_flip.exposure_levels(start, stop)
        assert len(levels) == used["numExposures"]
        assert levels[0] == np.float32(used["startExposure"])
        assert levels[-1] == pytest.approx(used["stopExposure"], abs=1e-5)
    with pytest.raises(ValueError, match="start <= stop"):
        hdr_flip.exposure_levels(2.0, 1.0)


def test_the_reference_side_is_computed_once_and_reused_only_for_the_same_content(monkeypatch):
    from mcbench.analysis import metrics

    _, image, reference = next(generic_pairs())
    calls = []
    original = hdr_flip.prepare_flip_reference
    monkeypatch.setattr(hdr_flip, "prepare_flip_reference", lambda *a, **k: calls.append(1) or original(*a, **k))
    metrics._PREPARED_REFERENCES.clear()
    first = flip_map(image, reference)
    again = [flip_map(image * scale, reference) for scale in (1.0, 0.5, 2.0)]
    assert len(calls) == 1
    np.testing.assert_array_equal(again[0], first)
    # the same array, changed in place: a new side, equal to a fresh computation
    changed = reference.copy()
    changed[3, 4] += 1.0
    reference[3, 4] += 1.0
    after = flip_map(image, reference)
    assert len(calls) == 2
    metrics._PREPARED_REFERENCES.clear()
    np.testing.assert_array_equal(after, flip_map(image, changed))
    assert not np.array_equal(after, first)


def test_exposures_split_into_passes_give_the_same_map(monkeypatch):
    """Large images evaluate their exposures a few at a time (memory): the map is the same."""
    _, image, reference = next(generic_pairs())
    start, stop = flip_exposure_range(reference)
    whole = hdr_flip.hdr_flip_map(image, hdr_flip.prepare_flip_reference(reference, start=start, stop=stop))
    monkeypatch.setattr(hdr_flip, "_PIXELS_PER_PASS", 1)
    prepared = hdr_flip.prepare_flip_reference(reference, start=start, stop=stop)
    assert len(hdr_flip._exposure_passes(prepared.exposures, image.shape[0] * image.shape[1])) == len(prepared.exposures)
    np.testing.assert_array_equal(hdr_flip.hdr_flip_map(image, prepared), whole)


def test_a_prepared_reference_refuses_an_image_of_another_shape():
    _, image, reference = next(generic_pairs())
    prepared = hdr_flip.prepare_flip_reference(reference, start=0.0, stop=2.0)
    with pytest.raises(ValueError, match="prepared reference"):
        hdr_flip.hdr_flip_map(image[:, :5], prepared)
