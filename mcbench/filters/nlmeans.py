"""Non-local means with variance cancellation (Rousselle, Knaus and Zwicker 2012), the
filter NFOR and RDFC use to prefilter features and to weight colours.

For pixels p and q = p + o and a patch P of radius ``patch_radius`` the distance is

    d²(p, q) = mean over n in P and channels c of
               [(u(p+n) - u(q+n))² - α (Var(p+n) + min(Var(p+n), Var(q+n)))]
               / (ε + k² (Var(p+n) + Var(q+n)))                                  (RKZ12 Eq. 5-6)

and the weight is w(p, q) = exp(-max(0, d²)). The filtered value is the w-weighted mean over
the (2·radius + 1)² window, clipped at image borders. ``guide`` may differ from the filtered
``values`` (cross filtering, e.g. weights from buffer B applied to buffer A).

Two implementations with the same result (tested to 1e-10 relative):

* :func:`nl_means_filter` -- compiled (numba): bands of ``BAND_ROWS`` image rows, and per band
  one window offset at a time the per-pixel distance map of the band plus the patch halo,
  separable direct patch sums (7 + 7 taps for 7x7 patches, edge rows/columns replicated),
  exp and the weighted sum of all value channels at once (one weight per pixel pair, shared by
  the K channels). Working set per band: two (rows + 2 F) x W maps and the band's (rows, W, K)
  accumulators, so it stays in cache at 512^2. Bands run in parallel (``prange``) with
  NUMBA_NUM_THREADS > 1; each band's arithmetic is identical either way.
* :func:`nl_means_filter_reference` -- the NumPy path (vectorised over the image, one offset at
  a time, patch sums by ``scipy.ndimage.uniform_filter`` in edge mode "nearest"), kept as the
  tests' truth; :func:`nl_means_weight_maps` yields its per-offset weight maps.

Compiled building blocks of the denoisers' own kernels, over a band of rows and one window
offset at a time: :func:`nl_means_distance_rows` (edge-replicated patch distances, channel mean
first), :func:`nl_means_patch_distance_maps` (truncated patches, several patch radii from one
per-pixel map; RDFC's colour weights) and :func:`nl_means_window_weights` (the weights of every
window offset of a band, pixel-major; NFOR's regression). All arithmetic is float64 (the
distances subtract variance terms of similar size, and the weights feed float64 sums).

Options that reproduce Tungsten's NL-means (``src/denoiser/NlMeans.hpp`` of tunabrain/tungsten at
88ea020, the NFOR authors' re-implementation; ``docs/fidelity_nfor.md``), all off by default:

* ``channels="min"``: one weight per pixel pair, the minimum over channels of the per-channel
  weights exp(-max(D_c, 0)) (Tungsten's regression weights, ``NlMeans.hpp:37-40,87``);
  ``channels="independent"``: value channel j is averaged with weights from guide channel
  j mod C alone and normalised on its own (``nlMeans<Vec3f>``, ``NlMeans.hpp:33-36,142-152``);
* ``borders="truncate"``: the patch mean runs over the pairs (p + n, p + n + o) that lie inside
  the image and divides by their count (Tungsten's box filter over the clipped region,
  ``NlMeans.hpp:62-67,83``, ``BoxFilter.hpp:53-89``) instead of replicating the image edges;
* ``clamp``: per-pixel, per-channel distances clipped before the patch mean (Tungsten: 1e4,
  ``NlMeans.hpp:53,76``).

These run in :func:`nl_means_channel_distance_rows` (direct, per channel, simpler and slower
than the default kernel); with ``channels="mean"``, ``borders="replicate"`` and no clamp the
default kernel runs.

``benchmarks/bench_nlmeans.py`` measures the compiled filter against the NumPy path
(``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_nlmeans.py --sizes 128 512``).
"""

from __future__ import annotations

import numpy as np
from numba import prange
from scipy.ndimage import uniform_filter

from mcbench.jit import cached_njit

__all__ = ["nl_means_filter", "nl_means_filter_reference", "nl_means_weight_maps",
           "nl_means_distance_rows", "nl_means_patch_distance_maps", "nl_means_channel_distance_rows",
           "nl_means_offset_weights", "nl_means_window_weights", "guide_planes",
           "BAND_ROWS", "CHANNEL_MODES", "BORDER_MODES"]

BAND_ROWS = 16   # rows per band of the compiled filter; affects speed only
#: Channel handling of the weights: "mean" (channel-mean distance, RKZ12 Eq. 5), "min" (minimum
#: per-channel weight), "independent" (one weight per value channel); codes of the kernels.
CHANNEL_MODES = {"mean": 0, "min": 1, "independent": 2}
#: Patch borders: "replicate" (edge replication, ÷(2F+1)²) or "truncate" (in-image pairs only).
BORDER_MODES = ("replicate", "truncate")



def _guide_and_variance(guide, guide_variance) -> tuple[np.ndarray, np.ndarray]:
    """The guide and its variance as (H, W, C) float64 (variance clamped at 0); a (H, W) guide
    gets one channel. ValueError when their shapes differ."""
    guide = np.asarray(guide, dtype=np.float64)
    variance = np.maximum(np.asarray(guide_variance, dtype=np.float64), 0.0)
    if guide.ndim == 2:
        guide, variance = guide[..., None], variance[..., None]
    if guide.shape != variance.shape:
        raise ValueError(f"guide {guide.shape} and guide_variance {variance.shape} differ in shape")
    return guide, variance

def _shifted(array: np.ndarray, dy: int, dx: int) -> tuple[np.ndarray, np.ndarray]:
    """``array`` sampled at (y + dy, x + dx) with edge replication, and the validity mask."""
    h, w = array.shape[:2]
    ys = np.clip(np.arange(h) + dy, 0, h - 1)
    xs = np.clip(np.arange(w) + dx, 0, w - 1)
    valid = ((np.arange(h) + dy >= 0) & (np.arange(h) + dy < h))[:, None] & \
            ((np.arange(w) + dx >= 0) & (np.arange(w) + dx < w))[None, :]
    return array[ys][:, xs], valid


def nl_means_weight_maps(guide: np.ndarray, guide_variance: np.ndarray, radius: int, patch_radius: int,
                         k: float, alpha: float = 1.0, epsilon: float = 1e-10):
    """Yield ``(dy, dx, weight, valid)`` for every window offset: weight (H, W) = w(p, p + o).

    guide, guide_variance: (H, W, C) float arrays; the variance is per pixel and channel.
    """
    guide, variance = _guide_and_variance(guide, guide_variance)
    size = 2 * patch_radius + 1
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            shifted, valid = _shifted(guide, dy, dx)
            shifted_variance, _ = _shifted(variance, dy, dx)
            numerator = (guide - shifted) ** 2 - alpha * (variance + np.minimum(variance, shifted_variance))
            distance = (numerator / (epsilon + k * k * (variance + shifted_variance))).mean(axis=2)
            if patch_radius > 0:
                distance = uniform_filter(distance, size=size, mode="nearest")
            weight = np.exp(-np.maximum(distance, 0.0))
            weight[~valid] = 0.0
            yield dy, dx, weight, valid


def nl_means_filter_reference(values: np.ndarray, guide: np.ndarray, guide_variance: np.ndarray,
                              radius: int = 5, patch_radius: int = 3, k: float = 0.5, alpha: float = 1.0,
                              epsilon: float = 1e-10) -> np.ndarray:
    """NumPy reference of :func:`nl_means_filter` (same arguments, same result to rounding)."""
    values = np.asarray(values, dtype=np.float64)
    squeeze = values.ndim == 2
    if squeeze:
        values = values[..., None]
    if values.shape[:2] != np.shape(guide)[:2]:
        raise ValueError(f"values {values.shape[:2]} and guide {np.shape(guide)[:2]} differ in size")
    total = np.zeros_like(values)
    weight_sum = np.zeros(values.shape[:2])
    for dy, dx, weight, _ in nl_means_weight_maps(guide, guide_variance, radius, patch_radius, k, alpha, epsilon):
        shifted, _ = _shifted(values, dy, dx)
        total += weight[..., None] * shifted
        weight_sum += weight
    out = total / weight_sum[..., None]
    return out[..., 0] if squeeze else out


# ---------------------------------------------------------------------------------------------
# Compiled path
# ---------------------------------------------------------------------------------------------

@cached_njit(error_model="numpy")
def _clamp(i, n):
    return 0 if i < 0 else (n - 1 if i >= n else i)


@cached_njit(error_model="numpy")
def _add_pixel_distances(guide, variance, yp, yq, x0, x1, dx, k2, alpha, epsilon, out):
    """out[i] += sum over the C channels of the per-pixel distance term (module docstring, RKZ12
    Eq. 5-6) of p = (yp, x0 + i) and p + o = (yq, x0 + i + dx), for i < x1 - x0, channels in
    order. guide, variance: (C, H, W) float64 planes; both column ranges must lie inside the
    image. The loop runs over views indexed from 0, so that it vectorises."""
    for ch in range(guide.shape[0]):
        gp, gq = guide[ch, yp, x0:x1], guide[ch, yq, x0 + dx:x1 + dx]
        vp_row, vq_row = variance[ch, yp, x0:x1], variance[ch, yq, x0 + dx:x1 + dx]
        for i in range(x1 - x0):
            vp = vp_row[i]
            vq = vq_row[i]
            diff = gp[i] - gq[i]
            out[i] += (diff * diff - alpha * (vp + min(vp, vq))) / (epsilon + k2 * (vp + vq))


@cached_njit(error_model="numpy")
def nl_means_distance_rows(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp,
                           dmap, hsum, out):
    """Patch distance d²(p, p + o) (module docstring, RKZ12 Eq. 5-6) for o = (dy, dx) and the
    pixels p of rows [y0, y0 + rows), written to ``out[:rows, :]``.

    guide, variance: (C, H, W) float64 planes (variance >= 0). Per-pixel distances, averaged
    over the C channels, are clipped at ``clamp`` (``np.inf``: no clipping) before the patch
    mean; patch and shifted pixels replicate the image edges. dmap, hsum: scratch of at least
    (rows + 2 patch, W). Pixels whose p + o leaves the image get a value too (edge-replicated
    shift); callers mask them.
    """
    c, h, w = guide.shape
    k2 = k * k
    ra = y0 - patch
    nr = rows + 2 * patch
    inv_c = 1.0 / c
    x0 = min(max(0, -dx), w)              # x in [x0, x1): x + dx inside the image, no clamping
    x1 = max(min(w, w - dx), x0)
    for r in range(nr):
        yp = _clamp(ra + r, h)
        yq = _clamp(yp + dy, h)
        drow = dmap[r]
        drow[:] = 0.0
        _add_pixel_distances(guide, variance, yp, yq, x0, x1, dx, k2, alpha, epsilon, drow[x0:x1])
        for ch in range(c):
            gp, gq = guide[ch, yp], guide[ch, yq]
            vp_row, vq_row = variance[ch, yp], variance[ch, yq]
            for x in range(w):
                if x >= x0 and x < x1:
                    continue
                xq = _clamp(x + dx, w)
                vp = vp_row[x]
                vq = vq_row[xq]
                diff = gp[x] - gq[xq]
                drow[x] += (diff * diff - alpha * (vp + min(vp, vq))) / (epsilon + k2 * (vp + vq))
        for x in range(w):
            acc = drow[x] * inv_c
            drow[x] = acc if acc < clamp else clamp
    if patch == 0:
        for r in range(rows):
            out[r, :w] = dmap[r, :w]
        return
    norm = 1.0 / ((2 * patch + 1) * (2 * patch + 1))
    lo = min(patch, w)                    # x in [lo, hi): the patch row lies inside the image
    hi = max(w - patch, lo)
    for r in range(nr):
        drow = dmap[r]
        hrow = hsum[r]
        hrow[:] = 0.0
        hv = hrow[lo:hi]
        for n in range(-patch, patch + 1):
            dv = drow[lo + n:hi + n]
            for i in range(hi - lo):
                hv[i] += dv[i]
        for x in range(w):
            if x >= lo and x < hi:
                continue
            s = 0.0
            for n in range(-patch, patch + 1):
                s += drow[_clamp(x + n, w)]
            hrow[x] = s
    for r in range(rows):
        y = y0 + r
        orow = out[r]
        orow[:w] = 0.0
        for n in range(-patch, patch + 1):
            hrow = hsum[_clamp(y + n, h) - ra]
            for x in range(w):
                orow[x] += hrow[x]
        for x in range(w):
            orow[x] *= norm


@cached_njit(error_model="numpy")
def nl_means_patch_distance_maps(guide, variance, y0, rows, dy, dx, k, alpha, epsilon, patch_radii, m, hs,
                                 out):
    """Patch distances d²(p, p + o) of the rows [y0, y0 + rows) for o = (dy, dx), one map per
    patch radius in ``patch_radii``, with truncated patches and no clamp: out[j, r, x] = the mean,
    over the patch offsets n whose pixels p + n and p + n + o both lie inside the image, of the
    channel mean of the per-pixel distance term (module docstring, RKZ12 Eq. 5-6). The
    per-pixel map is computed once and shared by the radii (RDFC's candidate filters).

    guide, variance: (C, H, W) float64 planes. m, hs: scratch of at least (rows + 2 max f, W).
    Horizontal patch sums run over n ascending, vertical ones over the rows ascending, then one
    division by the pair count. Entries whose p + o leaves the image are left unset (callers
    skip them).
    """
    nc, h, w = guide.shape
    fmax = 0
    for j in range(patch_radii.shape[0]):
        fmax = max(fmax, patch_radii[j])
    ra = max(y0 - fmax, 0)
    rb = min(y0 + rows + fmax, h)
    k2 = k * k
    x0 = max(0, -dx)
    x1 = min(w, w - dx)
    inv_nc = 1.0 / nc
    for yy in range(ra, rb):
        mrow = m[yy - ra]
        mrow[:] = 0.0
        yq = yy + dy
        if yq < 0 or yq >= h or x0 >= x1:
            continue
        mv = mrow[x0:x1]
        _add_pixel_distances(guide, variance, yy, yq, x0, x1, dx, k2, alpha, epsilon, mv)
        for i in range(x1 - x0):
            mv[i] *= inv_nc
    for j in range(patch_radii.shape[0]):
        f = patch_radii[j]
        for yy in range(ra, rb):
            mrow = m[yy - ra]
            hrow = hs[yy - ra]
            hrow[:] = 0.0
            for n in range(-f, f + 1):          # in-image horizontal patch sums, n ascending
                lo = min(max(0, -n), w)
                hi = max(min(w, w - n), lo)
                hv, mv = hrow[lo:hi], mrow[lo + n:hi + n]
                for i in range(hi - lo):
                    hv[i] += mv[i]
        for r in range(rows):
            y = y0 + r
            if y + dy < 0 or y + dy >= h:
                continue
            ya = max(y - f, 0)
            yb = min(y + f, h - 1)
            # in-image patch rows whose shifted row is inside too (the valid pairs), per axis
            cy = min(yb, h - 1 - dy) - max(ya, -dy) + 1
            orow = out[j, r]
            orow[:] = 0.0
            for yy in range(ya, yb + 1):
                hrow = hs[yy - ra]
                for x in range(w):
                    orow[x] += hrow[x]
            for x in range(x0, x1):
                cx = min(min(x + f, w - 1), w - 1 - dx) - max(max(x - f, 0), -dx) + 1
                orow[x] /= cy * cx


@cached_njit(parallel=True, error_model="numpy")
def _nl_means_kernel(values, guide, variance, radius, patch, k, alpha, epsilon, band):
    """values: (K, H, W); guide, variance: (C, H, W) float64 planes. Returns (K, H, W)."""
    nv, h, w = values.shape
    out = np.empty((nv, h, w))
    nbands = (h + band - 1) // band
    for bi in prange(nbands):
        y0 = bi * band
        rows = min(h, y0 + band) - y0
        dmap = np.empty((rows + 2 * patch, w))
        hsum = np.empty((rows + 2 * patch, w))
        dist = np.empty((rows, w))
        total = np.zeros((nv, rows, w))
        wsum = np.zeros((rows, w))
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                nl_means_distance_rows(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon,
                                       np.inf, dmap, hsum, dist)
                x0 = max(0, -dx)
                x1 = min(w, w - dx)
                for r in range(rows):
                    yq = y0 + r + dy
                    if yq < 0 or yq >= h:
                        continue
                    drow = dist[r]
                    for x in range(x0, x1):
                        drow[x] = np.exp(-max(drow[x], 0.0))      # the weight w(p, p + o)
                        wsum[r, x] += drow[x]
                    for ch in range(nv):
                        trow, vrow = total[ch, r], values[ch, yq]
                        for x in range(x0, x1):
                            trow[x] += drow[x] * vrow[x + dx]
        for ch in range(nv):
            for r in range(rows):
                for x in range(w):
                    out[ch, y0 + r, x] = total[ch, r, x] / wsum[r, x]
    return out


@cached_njit(error_model="numpy")
def nl_means_channel_distance_rows(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp,
                                   truncate, dmap, hsum, out):
    """Per-channel patch distances D_c(p, p + o) for o = (dy, dx) and the pixels p of rows
    [y0, y0 + rows), written to ``out[c, :rows, :]`` (``out``: (C, >= rows, W)).

    guide, variance: (C, H, W) float64 planes (variance >= 0, already multiplied by any variance
    scale). Per-pixel distances (module docstring, one channel each) are clipped at ``clamp``
    per channel before the patch mean. ``truncate`` False: patch and shifted pixels replicate
    the image edges and the mean divides by (2F + 1)^2 (as :func:`nl_means_distance_rows`);
    True: only pairs with p + n and p + n + o inside the image count and the mean divides by
    their number (Tungsten, ``NlMeans.hpp:62-67,83``); pixels whose p + o leaves the image get 0
    (callers mask them). dmap, hsum: scratch of at least (rows + 2 patch, W).
    """
    c, h, w = guide.shape
    k2 = k * k
    ra = y0 - patch
    nr = rows + 2 * patch
    norm = 1.0 / ((2 * patch + 1) * (2 * patch + 1))
    for ch in range(c):
        for r in range(nr):
            drow = dmap[r]
            y = ra + r
            if truncate:
                if y < 0 or y >= h or y + dy < 0 or y + dy >= h:
                    drow[:w] = 0.0
                    continue
                yp, yq = y, y + dy
            else:
                yp = _clamp(y, h)
                yq = _clamp(yp + dy, h)
            for x in range(w):
                xq = x + dx
                if truncate:
                    if xq < 0 or xq >= w:
                        drow[x] = 0.0
                        continue
                else:
                    xq = _clamp(xq, w)
                vp = variance[ch, yp, x]
                vq = variance[ch, yq, xq]
                diff = guide[ch, yp, x] - guide[ch, yq, xq]
                d = (diff * diff - alpha * (vp + min(vp, vq))) / (epsilon + k2 * (vp + vq))
                drow[x] = d if d < clamp else clamp
        for r in range(nr):
            for x in range(w):
                s = 0.0
                for n in range(-patch, patch + 1):
                    xn = x + n
                    if truncate:
                        if xn >= 0 and xn < w:
                            s += dmap[r, xn]          # out-of-image pairs hold 0
                    else:
                        s += dmap[r, _clamp(xn, w)]
                hsum[r, x] = s
        for r in range(rows):
            y = y0 + r
            cy = 0
            for n in range(-patch, patch + 1):
                if 0 <= y + n < h and 0 <= y + n + dy < h:
                    cy += 1
            for x in range(w):
                s = 0.0
                for n in range(-patch, patch + 1):
                    s += hsum[r + patch + n, x]       # rows outside the image hold 0 (truncate)
                if truncate:
                    cx = 0
                    for n in range(-patch, patch + 1):
                        if 0 <= x + n < w and 0 <= x + n + dx < w:
                            cx += 1
                    out[ch, r, x] = s / (cx * cy) if cx * cy > 0 else 0.0
                else:
                    out[ch, r, x] = s * norm


@cached_njit(error_model="numpy")
def nl_means_offset_weights(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp, truncate,
                            mode, dmap, hsum, dist, out):
    """Weights w(p, p + o) of one offset for the rows [y0, y0 + rows) into ``out[:rows, :]``, one
    per pixel pair: ``mode`` 0 exp(-max(mean_c D_c, 0)), 1 min_c exp(-max(D_c, 0)) (Tungsten's
    regression weights); 0 where p + o leaves the image. D_c from
    :func:`nl_means_channel_distance_rows` (same arguments); dist: scratch (C, rows, W)."""
    c, h, w = guide.shape
    nl_means_channel_distance_rows(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp,
                                   truncate, dmap, hsum, dist)
    for r in range(rows):
        inside_y = 0 <= y0 + r + dy < h
        for x in range(w):
            if not (inside_y and 0 <= x + dx < w):
                out[r, x] = 0.0
                continue
            if mode == 1:
                d = dist[0, r, x]
                for ch in range(1, c):
                    d = max(d, dist[ch, r, x])
            else:
                d = 0.0
                for ch in range(c):
                    d += dist[ch, r, x]
                d /= c
            out[r, x] = np.exp(-d) if d > 0.0 else 1.0


@cached_njit(error_model="numpy")
def nl_means_window_weights(guide, variance, y0, y1, radius, patch, k, alpha, epsilon, clamp, truncate=False,
                            mode=0):
    """NL-means weights w(p, p + o) of every window offset o for the pixels p of rows [y0, y1):
    (y1 - y0, W, (2R + 1)^2), pixel-major, offset index (dy + R) (2R + 1) + (dx + R); 0 where
    p + o leaves the image. guide, variance: (C, H, W) float64 planes (NFOR's regression weights).

    Default (``truncate`` False, ``mode`` 0): distances of :func:`nl_means_distance_rows`
    (channel mean clipped at ``clamp``, edge-replicated patches), weight exp(-d) (1 for d <= 0).
    ``truncate`` (truncated patch means) or ``mode`` 1 (minimum per-channel weight) take
    Tungsten's path, :func:`nl_means_offset_weights` (distances clipped per channel).
    """
    c, h, w = guide.shape
    rows = y1 - y0
    side = 2 * radius + 1
    out = np.empty((rows, w, side * side))
    dmap = np.empty((rows + 2 * patch, w))
    hsum = np.empty((rows + 2 * patch, w))
    dist = np.empty((rows, w))
    if truncate or mode != 0:
        dist_c = np.empty((c, rows, w))
        wmap = np.empty((rows, w))
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                o = (dy + radius) * side + (dx + radius)
                nl_means_offset_weights(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp,
                                        truncate, mode, dmap, hsum, dist_c, wmap)
                for r in range(rows):
                    for x in range(w):
                        out[r, x, o] = wmap[r, x]
        return out
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            o = (dy + radius) * side + (dx + radius)
            nl_means_distance_rows(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp,
                                   dmap, hsum, dist)
            for r in range(rows):
                inside_y = 0 <= y0 + r + dy < h
                for x in range(w):
                    if inside_y and 0 <= x + dx < w:
                        d = dist[r, x]
                        out[r, x, o] = np.exp(-d) if d > 0.0 else 1.0
                    else:
                        out[r, x, o] = 0.0
    return out


@cached_njit(parallel=True, error_model="numpy")
def _nl_means_channels_kernel(values, guide, variance, radius, patch, k, alpha, epsilon, clamp, truncate,
                              mode, band):
    """The optional-behaviour filter (module docstring): values (K, H, W); guide, variance
    (C, H, W) float64 planes; ``mode`` a :data:`CHANNEL_MODES` code. Returns (K, H, W)."""
    nv, h, w = values.shape
    c = guide.shape[0]
    out = np.empty((nv, h, w))
    nbands = (h + band - 1) // band
    for bi in prange(nbands):
        y0 = bi * band
        rows = min(h, y0 + band) - y0
        dmap = np.empty((rows + 2 * patch, w))
        hsum = np.empty((rows + 2 * patch, w))
        dist = np.empty((c, rows, w))
        wmap = np.empty((rows, w))
        total = np.zeros((nv, rows, w))
        wsum = np.zeros((nv, rows, w))
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                x0 = max(0, -dx)
                x1 = min(w, w - dx)
                if mode == 2:
                    nl_means_channel_distance_rows(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon,
                                                   clamp, truncate, dmap, hsum, dist)
                else:
                    nl_means_offset_weights(guide, variance, y0, rows, dy, dx, patch, k, alpha, epsilon, clamp,
                                            truncate, mode, dmap, hsum, dist, wmap)
                for r in range(rows):
                    yq = y0 + r + dy
                    if yq < 0 or yq >= h:
                        continue
                    for ch in range(nv):
                        trow, vrow, srow = total[ch, r], values[ch, yq], wsum[ch, r]
                        for x in range(x0, x1):
                            if mode == 2:
                                wt = np.exp(-max(dist[ch % c, r, x], 0.0))
                            else:
                                wt = wmap[r, x]
                            trow[x] += wt * vrow[x + dx]
                            srow[x] += wt
        for ch in range(nv):
            for r in range(rows):
                for x in range(w):
                    out[ch, y0 + r, x] = total[ch, r, x] / wsum[ch, r, x]
    return out


def _planes(array: np.ndarray) -> np.ndarray:
    """(H, W, C) -> contiguous (C, H, W) float64."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(array, dtype=np.float64), 2, 0))


def guide_planes(guide, guide_variance) -> tuple[np.ndarray, np.ndarray]:
    """The guide and its variance (clamped at 0) as contiguous (C, H, W) float64 planes, the
    input of the compiled kernels; a (H, W) guide gets one channel. ValueError when their
    shapes differ."""
    guide, variance = _guide_and_variance(guide, guide_variance)
    return _planes(guide), _planes(variance)


def nl_means_filter(values: np.ndarray, guide: np.ndarray, guide_variance: np.ndarray, radius: int = 5,
                    patch_radius: int = 3, k: float = 0.5, alpha: float = 1.0, epsilon: float = 1e-10, *,
                    channels: str = "mean", borders: str = "replicate", clamp: float | None = None) -> np.ndarray:
    """NL-means filter ``values`` (H, W, K) or (H, W) with weights computed on ``guide``
    (H, W, C) or (H, W) and its per-pixel, per-channel ``guide_variance`` (same shape).

    Returns float64 of the same shape as ``values``. The centre weight is 1, so the
    normalisation never divides by zero. Compiled; with the default options it equals
    :func:`nl_means_filter_reference`. ``channels`` ("mean", "min", "independent"), ``borders``
    ("replicate", "truncate") and ``clamp`` (per-pixel, per-channel distance clip; None: none)
    select Tungsten's behaviours (module docstring); any non-default option runs
    :func:`_nl_means_channels_kernel`.
    """
    if channels not in CHANNEL_MODES or borders not in BORDER_MODES:
        raise ValueError(f"channels {channels!r} (expected one of {sorted(CHANNEL_MODES)}), borders {borders!r} "
                         f"(expected one of {list(BORDER_MODES)})")
    values = np.asarray(values, dtype=np.float64)
    squeeze = values.ndim == 2
    if squeeze:
        values = values[..., None]
    guide, variance = _guide_and_variance(guide, guide_variance)
    if values.shape[:2] != guide.shape[:2]:
        raise ValueError(f"values {values.shape[:2]} and guide {guide.shape[:2]} differ in size")
    if channels == "mean" and borders == "replicate" and clamp is None:
        out = _nl_means_kernel(_planes(values), _planes(guide), _planes(variance), int(radius),
                               int(patch_radius), float(k), float(alpha), float(epsilon), BAND_ROWS)
    else:
        out = _nl_means_channels_kernel(_planes(values), _planes(guide), _planes(variance), int(radius),
                                        int(patch_radius), float(k), float(alpha), float(epsilon),
                                        np.inf if clamp is None else float(clamp), borders == "truncate",
                                        CHANNEL_MODES[channels], BAND_ROWS)
    out = np.moveaxis(out, 0, 2)
    return np.ascontiguousarray(out[..., 0] if squeeze else out)
