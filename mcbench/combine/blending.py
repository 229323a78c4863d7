"""Per-pixel weighted sums of several images: the combination of Zheng et al. 2021 Eq. 3 / 35,

    z(p) = sum_i w_i(p) y_i(p)        per pixel p and channel,

with one weight map w_i (N, H, W, C) per input image y_i. Every sum is float64.

* :func:`combine_with` -- arrays in, one ``einsum`` (the ensemble's guide images, the one-hot
  selection's blends);
* :func:`blend` and :func:`blend_band` -- the inputs as :class:`mcbench.io.buffers.Denoised`,
  accumulated one input at a time in input order, optionally on a band of rows only, so that an
  input's images may be array-likes read from their files by rows (``x[y0:y1]``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["combine_with", "blend", "blend_band"]


def combine_with(weights, denoised) -> np.ndarray:
    """Eq. 3 / 35: sum_i w_i y_i per pixel-channel. (N, H, W, C) x (N, H, W, C) -> (H, W, C)
    float64 (one ``einsum`` of float64 copies)."""
    return np.einsum("nhwc,nhwc->hwc", np.asarray(weights, np.float64),
                     np.asarray(denoised, np.float64))


def blend(weights, inputs, which) -> np.ndarray:
    """Eq. 35 for image ``which`` (``"full"``, ``"a"``, ``"b"``) of the Denoised ``inputs``:
    sum_i w_i y_i accumulated in float64 one input at a time; weights (N, H, W, C). Returns
    (H, W, C) float64."""
    return blend_band(weights, inputs, slice(None), (which,))[which]


def blend_band(weights, inputs, rows, images=("full", "a", "b")) -> dict:
    """Eq. 35 on the rows ``rows`` (a slice) of the weights and of each input's images, for each
    image in ``images``, input by input (one read of an input's rows when it is read from its
    file): {image: (T, W, C) float64}, each accumulated in float64 in input order as
    :func:`blend`."""
    out = {}
    for w, d in zip(weights, inputs):
        w = w[rows]
        for which in images:
            term = w * np.asarray(d.image(which)[rows], np.float64)
            if which not in out:
                out[which] = np.zeros(term.shape)
            out[which] += term
    return out
