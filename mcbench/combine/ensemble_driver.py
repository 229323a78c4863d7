"""The ensemble (Zheng et al. 2021 Sec. 4) of a render's denoised images in one pass down the
image in bands of rows: raw weights solved block by block (:mod:`mcbench.combine.ensemble_weights`),
filtered band by band (:func:`mcbench.combine.weight_filter.filter_band`, Sec. 4.2) and blended
(:func:`mcbench.combine.blending.blend_band`, Eq. 35), so that whole arrays are only what it
returns. :func:`ensemble_in_bands` is the driver behind the ``ensemble`` combiner
(``methods/ensemble.py``, which holds the options' defaults and their meaning).
"""

from __future__ import annotations

import numpy as np

from mcbench.combine import weight_filter
from mcbench.combine.blending import blend_band, combine_with
from mcbench.combine.ensemble_weights import (check_away_steps, check_choices, check_shapes, nonfinite_pixels, raise_nonfinite,
                                              solve_block)
from mcbench.combine.weight_filter import filter_band, planar64, tile_rows

__all__ = ["ensemble_in_bands"]


class _BlockSolver:
    """The solve (Sec. 4.1) of blocks of ``block_pixels`` pixels of rows, in order,
    on demand (:meth:`until`): raw weights into ``raw`` (float32), and for the filter the guide
    z and Var[z] of the rows solved (float64, planar blocks) until :meth:`drop_before` lets them
    go, so only a band's halo of them is ever held. Counts non-finite input pixels block by
    block; at the first, it stops solving, counts the rest and raises the message of
    :func:`mcbench.combine.ensemble_weights.check_finite` (whole-image counts)."""

    def __init__(self, buffers, inputs, raw, *, guide, options, block_pixels):
        self.buffers, self.inputs, self.raw = buffers, inputs, raw
        self.guide, self.options = guide, options
        _, self.height, self.width, _ = raw.shape
        self.step = max(1, block_pixels // max(self.width, 1))
        self.next_row = 0
        self.blocks: list[tuple[int, np.ndarray, np.ndarray]] = []   # (first row, z, Var[z])

    def _block(self, rows):
        xa = np.asarray(self.buffers.color_a[rows], np.float64)
        xb = np.asarray(self.buffers.color_b[rows], np.float64)
        ya, yb, yf = (np.empty((len(self.inputs),) + xa.shape) for _ in range(3))
        for i, d in enumerate(self.inputs):    # input by input: one read of a file's rows
            ya[i], yb[i], yf[i] = d.a[rows], d.b[rows], d.full[rows]
        block = {"color_a": xa, "color_b": xb, "denoised_a": ya, "denoised_b": yb,
                 "denoised_full": yf}
        if self.guide:   # the filter's features: checked here too when read from files by rows
            for name in ("albedo", "normal"):
                layer = getattr(self.buffers, name)
                if not isinstance(layer, np.ndarray):
                    block[name] = np.asarray(layer[rows])
        return block

    def _raise_nonfinite(self, bad):
        for y0 in range(self.next_row, self.height, self.step):
            block = self._block(slice(y0, min(self.height, y0 + self.step)))
            for name, array in block.items():
                bad[name] = bad.get(name, 0) + nonfinite_pixels([array])
        raise_nonfinite(bad)

    def until(self, row):
        """Solve blocks until every row < ``row`` is."""
        while self.next_row < min(row, self.height):
            y0 = self.next_row
            rows = slice(y0, min(self.height, y0 + self.step))
            block = self._block(rows)
            # a NaN/Inf makes the sum non-finite (an overflowing sum only costs the exact count)
            if not all(np.isfinite(a.sum()) for a in block.values()):
                bad = {name: nonfinite_pixels([a]) for name, a in block.items()}
                if any(bad.values()):
                    self.next_row = rows.stop
                    self._raise_nonfinite(bad)
            ya, yb = block["denoised_a"], block["denoised_b"]
            w, _ = solve_block(block["color_a"], block["color_b"], ya, yb, first_row=y0,
                                **self.options)
            self.raw[:, rows] = w
            if self.guide:
                z = planar64(combine_with(w, block["denoised_full"]))
                var = planar64(0.5 * (combine_with(w, ya) - combine_with(w, yb)) ** 2)
                self.blocks.append((y0, z, var))
            self.next_row = rows.stop

    def guide_rows(self, v0, v1):
        """z and Var[z] of the rows v0 .. v1 - 1 (solved, not dropped): planar (C, v1 - v0, W)."""
        parts = [(max(v0, y0) - y0, min(v1, y0 + z.shape[1]) - y0, z, var)
                 for y0, z, var in self.blocks if y0 < v1 and y0 + z.shape[1] > v0]
        if len(parts) == 1:
            a, b, z, var = parts[0]
            return z[:, a:b], var[:, a:b]
        return (np.concatenate([z[:, a:b] for a, b, z, _ in parts], axis=1),
                np.concatenate([var[:, a:b] for a, b, _, var in parts], axis=1))

    def drop_before(self, row):
        """Let the guide blocks that end at or before ``row`` go."""
        self.blocks = [b for b in self.blocks if b[0] + b[1].shape[1] > row]


def _checked_shape(buffers, inputs, *, away_steps, variance_sum_floor: float, **choices) -> tuple[int, ...]:
    """The render's (H, W, C), refused (ValueError) without inputs, with an option not one of its
    ``choices``, or with an input image of another shape."""
    if not inputs:
        raise ValueError("the ensemble needs at least one input")
    check_choices(**choices)
    check_away_steps(away_steps)
    if not (np.isfinite(variance_sum_floor) and variance_sum_floor >= 0):
        raise ValueError(f"ensemble variance_sum_floor must be finite and >= 0, got {variance_sum_floor!r}")
    xa, xb = buffers.color_a, buffers.color_b
    shape = tuple(np.shape(xa))
    for i, d in enumerate(inputs):
        for which in ("full", "a", "b"):
            if tuple(np.shape(d.image(which))) != shape:
                raise ValueError(f"ensemble input {i} ({d.source}) image {which} has shape "
                                 f"{np.shape(d.image(which))}, the render's is {shape}")
    check_shapes(np.empty(shape, np.uint8), np.empty(np.shape(xb), np.uint8),
                 np.empty((1,) + shape, np.uint8), np.empty((1,) + shape, np.uint8))
    return shape


def _solve_filter_blend_bands(solve, buffers, inputs, raw, filt, images, *, passes: dict | None,
                              options: dict) -> None:
    """One pass down the image in bands (:func:`ensemble_in_bands`): each band's rows solved as
    far as its halo needs, the band filtered (``passes``: the weight filter's passes, ``None``
    without the filter) into ``filt`` and blended into ``images``."""
    h, wd = raw.shape[1:3]
    step = max(1, weight_filter.FILTER_BLOCK_PIXELS // max(wd, 1))
    for y0 in range(0, h, step):
        y1 = min(h, y0 + step)
        if passes is not None:
            v0, v1 = tile_rows(y0, y1, h, **passes)[2]
            solve.until(v1)
            z, var = solve.guide_rows(v0, v1)
            filt[:, y0:y1] = filter_band(raw, y0, y1, z, var, v0, buffers.albedo, buffers.normal,
                                         **options)
            del z, var
            solve.drop_before(tile_rows(y1, y1 + 1, h, **passes)[2][0])
        else:
            solve.until(y1)
        for key, rows in blend_band(filt, inputs, slice(y0, y1)).items():
            images[key][y0:y1] = rows
    solve.until(h)      # (h == 0)


def ensemble_in_bands(buffers, inputs, *, block_pixels: int, solver: str, seed: int, max_iterations: int,
                      tolerance: float, filter: bool, weights: str, channels: str, radius: int,
                      sigma_spatial: float, sigma_color: float, sigma_albedo: float, sigma_normal: float,
                      guide_variance_blur: str, outlier_removal: str, colour_distance: str,
                      filter_border: str, normal_features: str, variance_sum_floor: float,
                      start: str, away_steps: bool) -> tuple[dict, dict]:
    """Ensemble of the ``inputs`` of the render ``buffers`` (Sec. 4): raw weights from the half
    buffers, filtered (unless ``filter`` is False), combined (Eq. 35). ``buffers`` has the layers
    ``color_a``, ``color_b``, ``albedo``, ``normal`` as attributes and each input the images
    ``full``, ``a``, ``b`` (:class:`mcbench.io.buffers.RenderBuffers` and
    :class:`~mcbench.io.buffers.Denoised`). The options are those of the ``ensemble`` combiner
    (``methods/ensemble.py``, ``combine``), every one given.

    One pass down the image in bands of :data:`mcbench.combine.weight_filter.FILTER_BLOCK_PIXELS`
    pixels. For each band the rows are solved (blocks of ``block_pixels`` pixels, float64 copies
    of one block only) as far as its halo needs (:func:`mcbench.combine.weight_filter.tile_rows`:
    14 rows with the default passes), straight into the float32 raw weight maps, keeping the
    float64 guide z and Var[z] of those rows only; the band is filtered from its tile (float32
    but the colour term; :func:`mcbench.combine.weight_filter.filter_band`), written to the
    float32 filtered maps, and blended (Eq. 35, float64 accumulation) into the float32 images.
    What stays whole is what is returned: the three images and the 2N weight maps. The render's
    layers and the inputs' images are only ever indexed by rows (``x[y0:y1]``), so they may be
    array-likes read from their files by rows (:class:`mcbench.io.exr.LayerRows`): then no input
    is ever held whole. Each input row is read twice (solve, blend).

    Returns ``(images, extras)``: ``images`` {"full", "a", "b"} float32 (H, W, C); ``extras`` holds
    ``weights_raw_{i}`` and ``weights_filtered_{i}`` (H, W, 3) per input i (with
    ``filter=False`` the filtered maps equal the raw ones).

    Raises ValueError if there is no input, an option is not one of its choices, an input's
    image differs in shape from the render, an input holds NaN/Inf, or a combined image is not
    finite in float32.
    """
    shape = _checked_shape(buffers, inputs, away_steps=away_steps, variance_sum_floor=variance_sum_floor,
                           solver=solver, weights=weights, channels=channels, start=start,
                           guide_variance_blur=guide_variance_blur, colour_distance=colour_distance,
                           outlier_removal=outlier_removal, filter_border=filter_border,
                           normal_features=normal_features)
    n = len(inputs)
    h, wd, c = shape
    raw = np.empty((n, h, wd, c), np.float32)
    filt = np.empty((n, h, wd, c), np.float32) if filter else raw
    images = {key: np.empty((h, wd, c), np.float32) for key in ("full", "a", "b")}
    solve = _BlockSolver(buffers, inputs, raw, guide=filter, block_pixels=block_pixels,
                         options=dict(solver=solver, seed=seed, max_iterations=max_iterations,
                                      tolerance=tolerance, weights=weights, channels=channels,
                                      start=start, away_steps=away_steps))
    passes = dict(radius=radius, blur=guide_variance_blur == "gaussian9", outliers=outlier_removal != "none")
    statistics = (weight_filter.normal_statistics(buffers.normal)
                  if filter and normal_features == "standardised" else None)
    options = dict(radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                   sigma_albedo=sigma_albedo, sigma_normal=sigma_normal,
                   nonnegative=weights == "simplex", guide_variance_blur=guide_variance_blur,
                   outlier_removal=outlier_removal, colour_distance=colour_distance,
                   filter_border=filter_border, normal_statistics=statistics,
                   variance_sum_floor=variance_sum_floor, dtype=np.float32)
    _solve_filter_blend_bands(solve, buffers, inputs, raw, filt, images, passes=passes if filter else None,
                              options=options)
    extras = {}
    for i in range(n):
        extras[f"weights_raw_{i}"] = raw[i]
    for i in range(n):
        extras[f"weights_filtered_{i}"] = filt[i]
    bad = [key for key, image in images.items() if not np.isfinite(image).all()]
    if bad:
        raise ValueError(f"ensemble ({weights} weights) combined image(s) {bad} overflow "
                         f"float32")
    return images, extras
