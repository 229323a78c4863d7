"""The passes the authors' public code of Zheng et al. 2021 puts around the cross-bilateral filter
(:mod:`mcbench.filters.bilateral`): a Gaussian blur of the guide variance (:func:`gaussian_blur`,
OpenCV's kernel :func:`gaussian_kernel`), outlier removal (:func:`remove_outliers` (mcbench's),
:func:`remove_outlier_pixels` (as the code is written)) and :func:`reflect101_tile` for its
reflected borders.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.jit import cached_njit

__all__ = ["OPENCV_SMALL_KERNELS", "gaussian_kernel", "reflect101_tile", "gaussian_blur", "gaussian_blur_reference",
           "remove_outliers", "remove_outlier_pixels"]

#: OpenCV's fixed Gaussian taps: ``getGaussianKernel(k, 0)`` for k = 1 .. 9 returns these tables
#: (multiples of 1/256; measured with OpenCV 4.6, Debian 12's, which built the public code for
#: tests/data/golden/ensemble_cpp), not the sigma rule of larger sizes
OPENCV_SMALL_KERNELS = {1: (256,), 3: (64, 128, 64), 5: (16, 64, 96, 64, 16), 7: (8, 28, 56, 72, 56, 28, 8),
                        9: (4, 13, 30, 51, 60, 51, 30, 13, 4)}


def gaussian_kernel(kernel_size: int) -> np.ndarray:
    """The normalised 1-D Gaussian of OpenCV's ``GaussianBlur`` with sigma 0: for sizes up to 9
    OpenCV's fixed table (:data:`OPENCV_SMALL_KERNELS`, /256; for 9 it is the sigma-1.7 Gaussian
    rounded to 1/256, for 7 the public code's outlier blur [1, 3.5, 7, 9, 7, 3.5, 1] / 32), above 9
    sigma = 0.3 ((kernel_size - 1) / 2 - 1) + 0.8 and taps exp(-x^2 / (2 sigma^2)) at
    x = -(k - 1)/2 .. (k - 1)/2 divided by their sum. (kernel_size,) float64."""
    if kernel_size < 1 or kernel_size % 2 == 0:
        raise ValueError(f"kernel_size must be odd and positive, got {kernel_size}")
    if kernel_size in OPENCV_SMALL_KERNELS:
        return np.array(OPENCV_SMALL_KERNELS[kernel_size], dtype=np.float64) / 256.0
    sigma = 0.3 * ((kernel_size - 1) / 2 - 1) + 0.8
    x = np.arange(kernel_size) - (kernel_size - 1) / 2
    taps = np.exp(-x ** 2 / (2 * sigma ** 2))
    return taps / taps.sum()


@cached_njit(parallel=True, error_model="numpy")
def _blur_kernel(a, taps, idx0, idx1, n_out, c):
    """Rows, then columns: t[i] = sum_k taps[k] a[idx0[i + k]] (i < n_out), then
    out[:, x] = sum_k taps[k] t[:, idx1[x + k]], each sum from 0.0 with k ascending; a (T, W C)
    float64, idx0 / idx1 the padded rows' / columns' sources. Each row of t is padded once, so
    the column taps run over contiguous memory. Returns (n_out, W C)."""
    m = a.shape[1]
    w = m // c
    t_rows = np.zeros((n_out, m))
    for i in prange(n_out):
        for k in range(taps.shape[0]):
            tap = taps[k]
            src = idx0[i + k]
            for j in range(m):
                t_rows[i, j] += tap * a[src, j]
    out = np.zeros((n_out, m))
    for y in prange(n_out):
        padded = np.empty(idx1.shape[0] * c)
        for x in range(idx1.shape[0]):
            for ch in range(c):
                padded[x * c + ch] = t_rows[y, idx1[x] * c + ch]
        for k in range(taps.shape[0]):
            tap = taps[k]
            off = k * c
            for j in range(m):
                out[y, j] += tap * padded[off + j]
    return out


def _reflect_index(length: int, r: int) -> np.ndarray:
    """Source index of each of the length + 2 r padded positions: BORDER_REFLECT_101 (NumPy's
    "reflect", repeated for short axes), "edge" for an axis of length 1. int64."""
    return np.pad(np.arange(length), r, mode="reflect" if length > 1 else "edge")


def reflect101_tile(array, *, radius: int, first_row: int = 0, height: int | None = None,
                    rows: tuple[int, int] | None = None, row_axis: int = 0) -> np.ndarray:
    """Rows r0 - radius .. r1 + radius - 1 and columns -radius .. W + radius - 1 of an image,
    out-of-image positions reflected without repeating the edge (OpenCV's BORDER_REFLECT_101,
    :func:`_reflect_index`): the padding under which a clipped-window filter of those rows equals
    the public code's reflected windows (``cv::borderInterpolate``). ``array`` holds the rows
    ``first_row`` .. ``first_row + T - 1`` (along ``row_axis``; columns along the next axis) of
    an image of ``height`` rows (default: the tile is the image); ``rows=(r0, r1)`` default: the
    tile's rows. Every source row must be in the tile, else ``ValueError``. A copy, same dtype."""
    a = np.asarray(array)
    t_rows, width = a.shape[row_axis], a.shape[row_axis + 1]
    height = first_row + t_rows if height is None else int(height)
    r0, r1 = (first_row, first_row + t_rows) if rows is None else (int(rows[0]), int(rows[1]))
    idx0 = _reflect_index(height, radius)[r0:r1 + 2 * radius] - first_row
    if idx0.size and (idx0.min() < 0 or idx0.max() >= t_rows):
        raise ValueError(f"reflected rows {r0}:{r1} (radius {radius}) need image rows outside the tile "
                         f"{first_row}:{first_row + t_rows}")
    return np.take(np.take(a, idx0, axis=row_axis), _reflect_index(width, radius), axis=row_axis + 1)


def gaussian_blur(image, *, kernel_size: int = 9, rows: tuple[int, int] | None = None,
                  first_row: int = 0, height: int | None = None) -> np.ndarray:
    """Separable Gaussian blur of an (H, W) or (H, W, C) image with :func:`gaussian_kernel`,
    borders reflected without repeating the edge pixel (OpenCV's default BORDER_REFLECT_101,
    NumPy's ``pad`` mode "reflect"; an axis of length 1 is constant): rows first, then columns,
    each output the sum of tap x value from k = 0 up (the order of the NumPy formulation
    ``out += tap * shifted``, so the result is the same bit for bit; tests/filters/test_bilateral.py).

    A tile: ``image`` holds the rows ``first_row`` .. ``first_row + T - 1`` of an image of
    ``height`` rows (default: the whole image), and ``rows=(r0, r1)`` asks for the blurred rows
    r0 .. r1 - 1 of the image (default: the tile's); every row within kernel_size // 2 of them
    (reflected at the image's borders) must be in the tile. Returns float64 of shape
    (r1 - r0, W[, C])."""
    a = np.asarray(image, np.float64)
    flat = a.ndim == 2
    if flat:
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {np.shape(image)}")
    taps = gaussian_kernel(kernel_size)
    r = kernel_size // 2
    t_rows, w, c = a.shape
    height = first_row + t_rows if height is None else int(height)
    r0, r1 = (first_row, first_row + t_rows) if rows is None else (int(rows[0]), int(rows[1]))
    idx0 = _reflect_index(height, r)[r0:r1 + 2 * r] - first_row
    if r1 > r0 and (idx0.min() < 0 or idx0.max() >= t_rows):
        raise ValueError(f"blurred rows {r0}:{r1} need image rows outside the tile "
                         f"{first_row}:{first_row + t_rows}")
    if r1 <= r0:
        out = np.zeros((0, w, c))
    else:
        out = _blur_kernel(np.ascontiguousarray(a).reshape(t_rows, w * c), taps, idx0,
                           _reflect_index(w, r), r1 - r0, c).reshape(r1 - r0, w, c)
    return out[..., 0] if flat else out


def gaussian_blur_reference(image, *, kernel_size: int = 9) -> np.ndarray:
    """:func:`gaussian_blur` in NumPy (pad, then ``out += tap * shifted`` per axis), the
    reference of its tests. Returns float64 of the image's shape."""
    a = np.asarray(image, np.float64)
    taps = gaussian_kernel(kernel_size)
    r = kernel_size // 2
    for axis in (0, 1):
        length = a.shape[axis]
        widths = [(0, 0)] * a.ndim
        widths[axis] = (r, r)
        padded = np.pad(a, widths, mode="reflect" if length > 1 else "edge")
        out = np.zeros_like(a)
        window = [slice(None)] * a.ndim
        for k, tap in enumerate(taps):
            window[axis] = slice(k, k + length)
            out += tap * padded[tuple(window)]
        a = out
    return a


@cached_njit(parallel=True, error_model="numpy")
def _outlier_kernel(maps, radius, threshold):
    """maps (G, H, W, C); per (map, channel) in parallel: the clipped window's sums of the values
    and their squares as running column sums (add the row entering the window, subtract the one
    leaving it) and a running sum along the row, in float64. Returns the cleaned maps."""
    G, H, W, C = maps.shape
    out = np.empty_like(maps)
    for item in prange(G * C):
        g = item // C
        c = item % C
        col = np.zeros(W)
        col2 = np.zeros(W)
        top = 0                   # rows [top, bottom) are in the column sums
        bottom = 0
        for y in range(H):
            lo = max(0, y - radius)
            hi = min(H, y + radius + 1)
            while bottom < hi:
                for x in range(W):
                    v = float(maps[g, bottom, x, c])
                    col[x] += v
                    col2[x] += v * v
                bottom += 1
            while top < lo:
                for x in range(W):
                    v = float(maps[g, top, x, c])
                    col[x] -= v
                    col2[x] -= v * v
                top += 1
            rows = hi - lo
            s = 0.0
            s2 = 0.0
            left = 0
            right = 0
            for x in range(W):
                xl = max(0, x - radius)
                xr = min(W, x + radius + 1)
                while right < xr:
                    s += col[right]
                    s2 += col2[right]
                    right += 1
                while left < xl:
                    s -= col[left]
                    s2 -= col2[left]
                    left += 1
                v = float(maps[g, y, x, c])
                others = rows * (xr - xl) - 1
                out[g, y, x, c] = maps[g, y, x, c]
                if others > 0:
                    mean = (s - v) / others
                    var = max((s2 - v * v) / others - mean * mean, 0.0)
                    if abs(v - mean) > threshold * np.sqrt(var):
                        out[g, y, x, c] = mean
    return out


def remove_outliers(maps, *, radius: int = 3, threshold: float = 2.5) -> np.ndarray:
    """The public code's outlier pass over filtered maps (``remove_outliers<3>(f, 2.5)``), our
    reading. For each map, pixel and channel independently: the mean m and the (population)
    standard deviation s of the *other* pixels of the (2 radius + 1)^2 window (the centre is
    left out, as the public code does, so an outlier does not inflate its own s; the window is
    clipped at the image borders like the bilateral filter's); a value with |v - m| > threshold s
    is replaced by m. (The public code instead replaces the whole pixel, all channels, by a
    7 x 7 Gaussian blur of the map when any channel is an outlier, and reflects at the borders.)
    Window statistics in float64 (running sums), O(1) per value.

    maps : (G, H, W, C) or (H, W, C), float32 or float64. Returns a new array of the same shape
    and dtype; the caller re-projects weights onto their constraint (the replacement is per
    map)."""
    a = np.asarray(maps)
    if a.dtype not in (np.float32, np.float64):
        a = a.astype(np.float64)
    stacked = np.ascontiguousarray(a if a.ndim == 4 else a[None])
    if stacked.ndim != 4:
        raise ValueError(f"maps must be (G, H, W, C) or (H, W, C), got shape {np.shape(maps)}")
    out = _outlier_kernel(stacked, int(radius), float(threshold))
    return out if a.ndim == 4 else out[0]


def remove_outlier_pixels(maps, *, radius: int = 3, threshold: float = 2.5, first_row: int = 0,
                          height: int | None = None, rows: tuple[int, int] | None = None) -> np.ndarray:
    """The public code's outlier pass over filtered maps as it is written (``filter.h:83-136``,
    ``remove_outliers<3>(f, 2.5)`` at ``main.cpp:165``), per map: with m_c and s_c the mean and
    sqrt((1 - 1/n) (E[x^2] - E[x]^2)) of channel c over the n = (2 radius + 1)^2 - 1 other pixels
    of the window (borders reflected, BORDER_REFLECT_101), a pixel where *any* channel has
    |v_c - m_c| >= threshold s_c takes, in all channels, the map's (2 radius + 1)^2 Gaussian blur
    (:func:`gaussian_blur`, OpenCV's sigma-0 kernel: for 7 x 7 its fixed taps
    [1, 3.5, 7, 9, 7, 3.5, 1] / 32, borders reflected); the others keep their value. A negative
    E[x^2] - E[x]^2 (rounding) gives s_c = NaN there, which no comparison passes, as in the C++.
    Statistics and blur in float64 (the C++: float32), O((2 radius + 1)^2) per value.

    maps : (G, T, W, C) or (T, W, C): the rows ``first_row`` .. ``first_row + T - 1`` of maps of
    ``height`` rows (default: whole maps); ``rows=(r0, r1)``: the output rows (default: the
    tile's), every row within ``radius`` of them (reflected) must be in the tile. Returns
    (G, r1 - r0, W, C) (or without G) of the maps' dtype (float32 or float64); the caller
    re-projects weights onto their constraint (a replaced pixel's weights need not sum to 1)."""
    a = np.asarray(maps)
    dtype = a.dtype if a.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    stacked = a if a.ndim == 4 else a[None]
    if stacked.ndim != 4:
        raise ValueError(f"maps must be (G, H, W, C) or (H, W, C), got shape {np.shape(maps)}")
    g_maps, t_rows, width, channels = stacked.shape
    height = first_row + t_rows if height is None else int(height)
    r0, r1 = (first_row, first_row + t_rows) if rows is None else (int(rows[0]), int(rows[1]))
    padded = reflect101_tile(np.asarray(stacked, np.float64), radius=radius, first_row=first_row,
                             height=height, rows=(r0, r1), row_axis=1)
    n_rows, k = r1 - r0, 2 * radius + 1
    total = np.zeros((g_maps, n_rows, width, channels))
    total_sq = np.zeros_like(total)
    for dy in range(k):
        for dx in range(k):
            if dy == radius and dx == radius:
                continue
            v = padded[:, dy:dy + n_rows, dx:dx + width]
            total += v
            total_sq += v * v
    n = k * k - 1
    mean = total / n
    spread = (1.0 - 1.0 / n) * (total_sq / n - mean * mean)
    with np.errstate(invalid="ignore"):
        sigma = np.where(spread >= 0, np.sqrt(np.maximum(spread, 0.0)), np.nan)
        centre = padded[:, radius:radius + n_rows, radius:radius + width]
        outlier = (np.abs(centre - mean) >= threshold * sigma).any(axis=-1)
    out = centre.copy()
    for g in range(g_maps):
        if outlier[g].any():
            blurred = gaussian_blur(stacked[g], kernel_size=k, rows=(r0, r1), first_row=first_row,
                                    height=height)
            out[g][outlier[g]] = blurred[outlier[g]]
    out = out.astype(dtype)
    return out if a.ndim == 4 else out[0]
