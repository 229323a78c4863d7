"""Small separable smoothings with kernels truncated (and renormalised) at the image borders, as
RDFC's authors' CUDA code has them (fbksd-package ``denoisers/RDFC/src/featurefilter.cu``).

* :func:`box_mean` -- ``conv_box`` (featurefilter.cu:255-280): a (2r+1)-tap box per axis, the
  mean over the in-image taps;
* :func:`pyramid_smooth` -- ``conv_pyr`` (featurefilter.cu:319-347): taps [v, 1, v] per axis
  (v = 0.1353 = e^-2 by default, featurefilter.h:148), the weighted mean over the in-image taps.
"""

from __future__ import annotations

import numpy as np

PYRAMID_TAP = 0.1353


def box_mean(image, radius: int) -> np.ndarray:
    """Mean over the in-image pixels of a (2 radius + 1)-tap box, rows then columns, of an
    (H, W) or (H, W, C) image; float64."""
    out = np.asarray(image, dtype=np.float64)
    for axis in (0, 1):
        n = out.shape[axis]
        pad = [(1, 0) if a == axis else (0, 0) for a in range(out.ndim)]
        c = np.cumsum(np.pad(out, pad), axis=axis)
        idx = np.arange(n)
        hi, lo = np.minimum(idx + radius, n - 1) + 1, np.maximum(idx - radius, 0)
        shape = [-1 if a == axis else 1 for a in range(out.ndim)]
        out = (np.take(c, hi, axis=axis) - np.take(c, lo, axis=axis)) / (hi - lo).reshape(shape)
    return out


def pyramid_smooth(image, tap: float = PYRAMID_TAP) -> np.ndarray:
    """Taps [tap, 1, tap] along rows then columns, normalised by the in-image taps' sum, of an
    (H, W) or (H, W, C) image; float64."""
    out = np.asarray(image, dtype=np.float64)
    for axis in (0, 1):
        n = out.shape[axis]
        moved = np.moveaxis(out, axis, 0)
        acc = moved.copy()
        wsum = np.ones(n)
        if n > 1:
            acc[1:] += tap * moved[:-1]
            acc[:-1] += tap * moved[1:]
            wsum[1:] += tap
            wsum[:-1] += tap
        out = np.moveaxis(acc / wsum.reshape((-1,) + (1,) * (moved.ndim - 1)), 0, axis)
    return out
