"""The Tungsten options of :func:`mcbench.filters.nlmeans.nl_means_filter` (per-channel weights,
truncated patch borders, per-channel distance clamp) against a brute-force loop written from the
definitions in the module docstring, the default options unchanged, the window weights (NFOR's
regression) with Tungsten's options and the truncated patch distance maps (RDFC's colour
distances) against a brute-force loop."""

import numpy as np
import pytest

from mcbench.filters.nlmeans import (nl_means_filter, nl_means_filter_reference, nl_means_patch_distance_maps,
                                     nl_means_window_weights)


def clampi(i, n):
    return min(max(i, 0), n - 1)


def brute_force(values, guide, variance, radius, patch, k, epsilon, channels, truncate, clamp=np.inf):
    """Per pixel p and offset o: D_c = mean over the patch pairs (p+n, p+n+o) of the clipped
    per-channel distance; truncated: only pairs inside the image, edge-replicated otherwise."""
    h, w, c = guide.shape
    nv = values.shape[2]
    out = np.zeros_like(values)
    for y in range(h):
        for x in range(w):
            total, wsum = np.zeros(nv), np.zeros(nv)
            for qy in range(max(0, y - radius), min(h, y + radius + 1)):
                for qx in range(max(0, x - radius), min(w, x + radius + 1)):
                    dy, dx = qy - y, qx - x
                    dsum, count = np.zeros(c), 0
                    for ny in range(-patch, patch + 1):
                        for nx in range(-patch, patch + 1):
                            py, px = y + ny, x + nx
                            sy, sx = py + dy, px + dx
                            if truncate:
                                if not (0 <= py < h and 0 <= px < w and 0 <= sy < h and 0 <= sx < w):
                                    continue
                            else:
                                py, px = clampi(py, h), clampi(px, w)
                                sy, sx = clampi(py + dy, h), clampi(px + dx, w)
                            vp, vq = variance[py, px], variance[sy, sx]
                            d = ((guide[py, px] - guide[sy, sx]) ** 2 - (vp + np.minimum(vp, vq))) / \
                                (epsilon + k * k * (vp + vq))
                            dsum += np.minimum(d, clamp)
                            count += 1
                    dist = dsum / count
                    if channels == "mean":
                        wt = np.full(nv, np.exp(-max(dist.mean(), 0.0)))
                    elif channels == "min":
                        wt = np.full(nv, np.exp(-np.maximum(dist, 0.0)).min())
                    else:
                        wt = np.exp(-np.maximum(dist[np.arange(nv) % c], 0.0))
                    total += wt * values[qy, qx]
                    wsum += wt
            out[y, x] = total / wsum
    return out


@pytest.mark.parametrize("channels", ["mean", "min", "independent"])
@pytest.mark.parametrize("borders", ["replicate", "truncate"])
def test_options_match_brute_force(channels, borders):
    rng = np.random.default_rng(7)
    h, w = 9, 10
    guide = rng.random((h, w, 3))
    variance = rng.random((h, w, 3)) * 0.02
    variance[2:4, 3:6] = 0.0                      # zero-variance pixels: epsilon matters
    values = rng.random((h, w, 6))
    got = nl_means_filter(values, guide, variance, radius=3, patch_radius=2, k=0.7, epsilon=1e-7,
                          channels=channels, borders=borders, clamp=50.0)
    want = brute_force(values, guide, variance, 3, 2, 0.7, 1e-7, channels, borders == "truncate", clamp=50.0)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_truncate_differs_only_near_borders():
    rng = np.random.default_rng(8)
    guide, variance = rng.random((20, 21, 3)), rng.random((20, 21, 3)) * 0.05
    values = rng.random((20, 21, 3))
    a = nl_means_filter(values, guide, variance, radius=2, patch_radius=2, k=0.5)
    b = nl_means_filter(values, guide, variance, radius=2, patch_radius=2, k=0.5, borders="truncate")
    inner = (slice(4, -4), slice(4, -4))           # >= radius + patch from every border
    np.testing.assert_allclose(a[inner], b[inner], rtol=1e-12)
    assert np.abs(a - b).max() > 1e-3


def test_default_options_keep_the_default_kernel():
    """channels="mean", replicate borders and an infinite clamp through the optional kernel equal
    the default kernel to rounding."""
    rng = np.random.default_rng(9)
    guide, variance = rng.random((12, 11, 3)), rng.random((12, 11, 3)) * 0.05
    values = rng.random((12, 11, 2))
    default = nl_means_filter(values, guide, variance, radius=3, patch_radius=2, k=0.5)
    optional = nl_means_filter(values, guide, variance, radius=3, patch_radius=2, k=0.5, clamp=np.inf)
    np.testing.assert_allclose(optional, default, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(default, nl_means_filter_reference(values, guide, variance, 3, 2, 0.5), rtol=1e-10)


def test_rejects_unknown_options():
    x = np.zeros((4, 4))
    with pytest.raises(ValueError, match="channels"):
        nl_means_filter(x, x, x, channels="max")
    with pytest.raises(ValueError, match="borders"):
        nl_means_filter(x, x, x, borders="wrap")


def planes(array):
    return np.ascontiguousarray(np.moveaxis(array, 2, 0))


def truncated_distances(guide, variance, y, x, dy, dx, patch, k, eps, clamp=np.inf):
    """(C,): per channel, the mean over the in-image patch pairs (p + n, p + n + o) of the per-pixel
    distance (alpha = 1) clipped at ``clamp``."""
    h, w, c = guide.shape
    total, count = np.zeros(c), 0
    for ny in range(-patch, patch + 1):
        for nx in range(-patch, patch + 1):
            py, px, qy, qx = y + ny, x + nx, y + ny + dy, x + nx + dx
            if not (0 <= py < h and 0 <= px < w and 0 <= qy < h and 0 <= qx < w):
                continue
            vp, vq = variance[py, px], variance[qy, qx]
            d = ((guide[py, px] - guide[qy, qx]) ** 2 - (vp + np.minimum(vp, vq))) / (eps + k * k * (vp + vq))
            total += np.minimum(d, clamp)
            count += 1
    return total / count


def brute_weights(guide, variance, y, x, dy, dx, patch, k, eps, clamp):
    """min over channels of exp(-max(D_c, 0)), D_c the truncated patch mean of the clipped distance."""
    return np.exp(-np.maximum(truncated_distances(guide, variance, y, x, dy, dx, patch, k, eps, clamp), 0.0)).min()


def test_window_weights_truncated_min_match_brute_force():
    """NFOR's regression weights with Tungsten's options (truncated patches, minimum
    per-channel weight, per-channel clamp) against the definition."""
    rng = np.random.default_rng(4)
    h, w, r, f = 8, 9, 2, 2
    guide, variance = rng.random((h, w, 3)), rng.random((h, w, 3)) * 0.03
    got = nl_means_window_weights(planes(guide), planes(variance), 0, h, r, f, 0.8, 1.0, 1e-7, 1e4, True, 1)
    side = 2 * r + 1
    for y in range(h):
        for x in range(w):
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    o = (dy + r) * side + dx + r
                    if 0 <= y + dy < h and 0 <= x + dx < w:
                        want = brute_weights(guide, variance, y, x, dy, dx, f, 0.8, 1e-7, 1e4)
                        assert got[y, x, o] == pytest.approx(want, rel=1e-10, abs=1e-300)
                    else:
                        assert got[y, x, o] == 0.0


@pytest.mark.parametrize("y0, rows", [(0, 9), (3, 4)])
def test_patch_distance_maps_match_brute_force(y0, rows):
    """Truncated patch distances of several radii from one per-pixel map (RDFC's colour
    distances), for a band of rows, against the definition."""
    rng = np.random.default_rng(7)
    h, w = 9, 11
    guide, variance = rng.random((h, w, 3)), rng.random((h, w, 3)) * 0.05
    radii = np.array([1, 3, 0], dtype=np.int64)
    scratch = (rows + 2 * 3, w)
    for dy, dx in [(0, 0), (2, -3), (-4, 1), (0, 5)]:
        out = np.full((len(radii), rows, w), np.nan)
        nl_means_patch_distance_maps(planes(guide), planes(variance), y0, rows, dy, dx, 0.45, 1.0, 1e-10,
                                     radii, np.empty(scratch), np.empty(scratch), out)
        for j, f in enumerate(radii):
            for r in range(rows):
                for x in range(w):
                    if 0 <= y0 + r + dy < h and 0 <= x + dx < w:
                        want = truncated_distances(guide, variance, y0 + r, x, dy, dx, f, 0.45, 1e-10).mean()
                        assert out[j, r, x] == pytest.approx(want, rel=1e-12, abs=1e-12)
