"""Naive averaging of the combiner's inputs (Zheng et al. 2021 Sec. 5.2.5): the baseline that
gives every base denoiser the same weight 1/N, z = (1/N) sum_i y_i (Eq. 3 with w_i = 1/N).

Each image is averaged on its own: the full result is the mean of the inputs' full results,
A the mean of their A results, B the mean of their B results, so A still depends on A's samples
only when every input's A result does. No weight maps (they would be constant).
"""

from __future__ import annotations

import numpy as np

from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.combine.selection import check_finite_arrays
from mcbench.contracts.method import MethodSpec



def combine(buffers: RenderBuffers, inputs: list[Denoised]) -> Denoised:
    """Mean of the ``inputs``' full, A and B images ((H, W, 3) each), float32 results.

    Raises ValueError for no inputs, images of another shape than the render's, or NaN/Inf.
    """
    if not inputs:
        raise ValueError("naive_average needs at least one input")
    means = {}
    for which in ("full", "a", "b"):
        stack = np.stack([np.asarray(d.image(which), np.float64) for d in inputs])
        if stack.shape[1:3] != tuple(buffers.shape):
            raise ValueError(f"naive_average: input images {stack.shape[1:3]} differ from the "
                             f"render's {tuple(buffers.shape)} ({buffers.source})")
        check_finite_arrays({f"inputs' {which} images": stack}, what="naive_average")
        means[which] = stack.mean(axis=0).astype(np.float32)
    return Denoised(full=means["full"], a=means["a"], b=means["b"])


METHOD = MethodSpec(kind="combiner", label="Naive average", run=combine, comparison_role="naive average")
