"""Is a reference the expected value of a local render? A block test of two images with variances.

A stored reference R (rendered elsewhere, once, to a low noise floor) is used by a study only if
it agrees with this machine's own render X of the same scene (its highest-spp noisy render).
Both carry the per-pixel variance of their mean (``variance`` layers of :mod:`mcbench.render`),
V_R and V_X. If R and X estimate the same image, D = X - R has mean 0 and variance Var(X) + V_R
at every pixel, independently across pixels (independent samples).

The render's own estimate V_X is not trusted alone. A path tracer's samples are heavy-tailed
(caustics, light through glass: rare paths of high value); with N_X samples most pixels miss the
rare paths, so both their mean and their sample variance come out low (measured on the default
study's glass_caustics at 1024 spp: the median pixel's V_X is 1/8 of the variance its samples
really have). The reference's N_R samples (64 to 512 times more) see those paths, so its
per-sample variance N_R V_R is the steadier estimate, and the render's variance is taken as

    Var(X) = max(V_X, V_R N_R / N_X)                                        (1)

when both sample counts are given (``reference_spp``, ``render_spp``). Without (1) the check
refuses the correct references of glass_caustics (max |z| 8.9) and of most scenes at low spp.

Per block B of ``block`` x ``block`` pixels and per channel c, the mean difference and its
standard score are

    d_Bc = (1/n) sum_{p in B} D_pc,    Var(d_Bc) = (1/n^2) sum_{p in B} (Var(X) + V_R)_pc,
    z_Bc = d_Bc / sqrt(Var(d_Bc) + (floor * m_Bc)^2),                       (2)

with ``m_Bc`` the block's mean |R| and ``floor`` a relative tolerance (float32 storage, the
scenes' own numerical noise). Averaging n = 256 pixels makes z close to Gaussian even where
single pixels are heavy-tailed (fireflies), and a firefly raises its own pixel's variance
estimate with its value (one sample moves z by at most about 1). The blocks are taken on four
grids, offset by half a block in each direction, so that any block-sized region covers at least
9/16 of some block. Two statistics, each at false-alarm probability ``alpha`` under the Gaussian
approximation:

* local: max |z_Bc| over every grid > Phi^-1(1 - alpha / (2 m)) (Bonferroni over all m scores),
  a region that differs (a biased patch);
* global: per channel, (sum_B z_Bc^2 - k) / sqrt(2 k) over the k blocks of the first grid
  (independent blocks), its largest over the channels above the chi-square law's own upper
  alpha / 3 point in the same units ((chi2_k^-1(1 - alpha / 3) - k) / sqrt(2 k); the normal
  approximation's threshold would reject three times too often at k = 16): a small
  difference everywhere (a slightly different scene, another renderer version). One channel
  at a time because the channels of one block are strongly correlated (the same paths carry
  all three: on the default study's cornell_box the three channels' z agree to about 0.9), so
  a chi-square over all 3 k scores would count each block three times.

Blocks where the local render recorded no variance at all (every pixel Var(X) + V_R = 0, e.g.
the background of a scene) compare exactly: any difference beyond ``floor`` fails them. The
measured false-alarm rates on synthetic renders (Gaussian, log-normal and Pareto samples) are in
``tests/analysis/test_reference_check.py``; on real renders in ``docs/reference_store.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri, ndtri

__all__ = ["ReferenceAgreement", "reference_agreement"]


@dataclass(frozen=True)
class ReferenceAgreement:
    """The result of :func:`reference_agreement`: the largest block score ``max_z`` and where
    (``block_row``, ``block_column`` in pixels, ``channel``), its threshold; the largest
    channel's global statistic, that channel and the threshold; the number of block scores;
    whether both pass."""

    max_z: float
    block_row: int
    block_column: int
    channel: int
    local_threshold: float
    global_statistic: float
    global_channel: int
    global_threshold: float
    scores: int

    @property
    def passed(self) -> bool:
        return self.max_z <= self.local_threshold and self.global_statistic <= self.global_threshold

    def describe(self) -> str:
        """One line with the test's numbers (for an error message or a log)."""
        return (f"max |z| {self.max_z:.2f} (threshold {self.local_threshold:.2f}) in the block at row "
                f"{self.block_row}, column {self.block_column}, channel {'RGB'[self.channel]}; global "
                f"{self.global_statistic:.2f} in channel {'RGB'[self.global_channel]} (threshold "
                f"{self.global_threshold:.2f}); {self.scores} block scores")


def _block_sums(image: np.ndarray, block: int) -> np.ndarray:
    """(H // block, W // block, C) sums over whole blocks (a remainder at the edges is left out)."""
    h, w = (image.shape[0] // block) * block, (image.shape[1] // block) * block
    cropped = image[:h, :w]
    return cropped.reshape(h // block, block, w // block, block, -1).sum(axis=(1, 3))


def _block_scores(ref, ref_var, img, img_var, *, block: int, floor: float, row: int, column: int):
    """(|z| per block and channel, row, column) of the grid of blocks starting at (row, column)."""
    n = block * block
    window = (slice(row, None), slice(column, None))
    difference = _block_sums(img[window] - ref[window], block) / n
    variance = _block_sums(img_var[window] + ref_var[window], block) / (n * n)
    magnitude = _block_sums(np.abs(ref[window]), block) / n
    denominator = np.sqrt(variance + (floor * magnitude) ** 2)
    exact = denominator <= 0.0
    z = np.where(exact, np.where(np.abs(difference) > 0.0, np.inf, 0.0),
                 np.abs(difference) / np.where(exact, 1.0, denominator))
    return z, row, column


def reference_agreement(reference: np.ndarray, reference_variance: np.ndarray, render: np.ndarray,
                        render_variance: np.ndarray, *, reference_spp: int | None = None,
                        render_spp: int | None = None, block: int = 16, alpha: float = 1e-4,
                        floor: float = 1e-4) -> ReferenceAgreement:
    """Test whether ``reference`` and ``render`` (each (H, W, 3) linear radiance with the (H, W, 3)
    variance of its mean) estimate the same image (module docstring). ``reference_spp`` and
    ``render_spp``, the samples per pixel behind each, give the render's variance the floor of
    Eq. (1); without them the render's own variance is used as it is. ``ValueError`` for
    mismatched shapes, non-finite or negative variances, an image smaller than one block, or
    sample counts that are not both positive integers."""
    arrays = [np.asarray(a, dtype=np.float64) for a in (reference, reference_variance, render, render_variance)]
    shape = arrays[0].shape
    if len(shape) != 3 or shape[2] != 3 or any(a.shape != shape for a in arrays):
        raise ValueError(f"reference_agreement: every image must be (H, W, 3) of one shape, got "
                         f"{[a.shape for a in arrays]}")
    if any(not np.all(np.isfinite(a)) for a in arrays):
        raise ValueError("reference_agreement: an image or variance holds NaN/Inf")
    if np.any(arrays[1] < 0) or np.any(arrays[3] < 0):
        raise ValueError("reference_agreement: a variance is negative")
    if shape[0] < block or shape[1] < block:
        raise ValueError(f"reference_agreement: the image ({shape[1]} x {shape[0]}) is smaller than one block "
                         f"of {block} x {block}")
    if not (0 < alpha < 1) or floor < 0:
        raise ValueError(f"reference_agreement: alpha must be in (0, 1) and floor >= 0, got {alpha}, {floor}")
    counts = (reference_spp, render_spp)
    if counts != (None, None):
        if not all(isinstance(c, (int, np.integer)) and not isinstance(c, bool) and c > 0 for c in counts):
            raise ValueError(f"reference_agreement: reference_spp and render_spp must both be positive "
                             f"integers (or both None), got {reference_spp!r}, {render_spp!r}")
        arrays[3] = np.maximum(arrays[3], arrays[1] * (float(reference_spp) / float(render_spp)))   # Eq. (1)
    ref, ref_var, img, img_var = arrays
    half = block // 2
    grids = [_block_scores(ref, ref_var, img, img_var, block=block, floor=floor, row=row, column=column)
             for row, column in ((0, 0), (0, half), (half, 0), (half, half))
             if shape[0] - row >= block and shape[1] - column >= block]
    m = sum(int(z.size) for z, _, _ in grids)
    best = max(range(len(grids)), key=lambda g: float(np.max(grids[g][0])))
    z, row, column = grids[best]
    where = np.unravel_index(int(np.argmax(z)), z.shape)
    aligned = grids[0][0]                        # the global statistic: the independent blocks of one grid
    blocks = aligned.shape[0] * aligned.shape[1]         # an exact block that differs (z = inf) stays inf
    per_channel = (np.sum(aligned * aligned, axis=(0, 1)) - blocks) / math.sqrt(2.0 * blocks)
    global_channel = int(np.argmax(per_channel))
    return ReferenceAgreement(max_z=float(z[where]), block_row=row + int(where[0]) * block,
                              block_column=column + int(where[1]) * block, channel=int(where[2]),
                              local_threshold=float(ndtri(1.0 - alpha / (2.0 * m))),
                              global_statistic=float(per_channel[global_channel]), global_channel=global_channel,
                              global_threshold=float((chdtri(blocks, alpha / 3.0) - blocks) / math.sqrt(2.0 * blocks)),
                              scores=m)
