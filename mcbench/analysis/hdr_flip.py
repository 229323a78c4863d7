"""HDR-FLIP (Andersson et al. 2021) computed as NVIDIA's flip-evaluator 1.7 computes it, in float64,
with the reference's side computed once and reused for every image compared with it.

The steps follow the package's C++ (``src/cpp/FLIP.h`` of NVlabs/flip at 1eb247c, version
1.6.0.1, the newest source at hand; line numbers of that file. The 1.7 wheel also floors the median
luminance of the exposure range at float32's epsilon, which
:func:`mcbench.analysis.metrics.flip_exposure_range` does, checked against the wheel): per exposure e of the range (``evaluate``, l. 2329-2404)
both images are scaled by 2^e, tone-mapped by FLIP's ACES (``toneMap``, l. 1395) and clamped to
[0, 1]; then LDR-FLIP (``LDR_FLIP``, l. 2236):

1. linear RGB -> XYZ -> YCxCz (D65, l. 367 and 443);
2. the contrast sensitivity filters, separable with clamp-to-edge borders (``setSpatialFilters``,
   l. 1741; ``computeColorDifference``, l. 1830): Y and Cx by one normalised Gaussian each, Cz by
   the sum of two separable Gaussians normalised together (``separatedConvolutions.pdf``); radius
   ceil(3 sqrt(max b / (2 pi^2)) ppd) (l. 612);
3. back to linear RGB, clamped to [0, 1], to CIELab, Hunt-adjusted (a, b scaled by 0.01 L), the
   HyAB distance raised to q_c = 0.7 and remapped by p_c = 0.4, p_t = 0.95 against the distance
   of green to blue (l. 470-489, 1917-1937);
4. features of the *unfiltered* Y normalised to [0, 1] (``computeFeatureDifferenceAndFinalError``,
   l. 1944): first and second derivatives of a Gaussian of standard deviation 0.5 w ppd (w =
   0.082), radius ceil(3 sd), positive and negative lobes normalised apart (``setFeatureFilter``,
   l. 1780); edge = |(G'x, G'y) * Y|, point = |(G''x, G''y) * Y|; the feature difference
   (max(|Δedge|, |Δpoint|) / sqrt 2)^q_f, q_f = 0.5;
5. the error colour^(1 - feature), and over exposures the per-pixel maximum (l. 2046).

The exposure levels are computed as the package computes them, in float32 (start + i * step,
step = (stop - start) / (n - 1), n = max(2, ceil(stop - start)); l. 2363-2376).

**Departure from the package**: float64 throughout, where the package computes in float32 and sums
its mean in float32 sequentially. The maps agree within 6.3e-5 per pixel and the means within
2.2e-4 relative on the default study's images (``benchmarks/hdr_flip.py``, docs/measurements.md).
The largest differences are where an image equals the reference to float32 precision (a constant
background both reproduce): HyAB's 0.7 power and the feature's 0.5 power have infinite slope at 0,
so the package's float32 rounding of two equal values becomes an error of up to ~3e-4 there, which
float64 does not make. Why our own code: flip-evaluator's one entry point recomputes the
reference's tone mapping, filtering and features for every image, and one case compares some 80
images with one reference; with the reference's side kept (:class:`FlipReference`), a call costs
about a fifth of the package's (``benchmarks/hdr_flip.py``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import correlate1d

__all__ = ["ACES", "FlipReference", "PIXELS_PER_DEGREE", "exposure_levels", "prepare_flip_reference", "hdr_flip_map"]

#: FLIP's default viewing condition: 0.7 m from a 0.7 m wide monitor of 3840 pixels (l. 118).
PIXELS_PER_DEGREE = 0.7 * (3840.0 / 0.7) * (np.pi / 180.0)
# FLIP's constants (l. 125-134): colour q_c, p_c, p_t; feature width w (degrees) and q_f
_QC, _PC, _PT, _W, _QF = 0.7, 0.4, 0.95, 0.082, 0.5
# the contrast sensitivity functions' Gaussians a * sqrt(pi / b) * exp(-pi^2 x^2 / b) (l. 567):
# Y (a1, b1), Cx (a1, b1), Cz (a1, b1) + (a2, b2); the b2 of Y and Cx enter only the radius
_A1, _B1 = (1.0, 1.0, 34.1), (0.0047, 0.0053, 0.04)
_A2, _B2 = (0.0, 0.0, 13.5), (1.0e-5, 1.0e-5, 0.025)
# FLIP's ACES (l. 138): (a2 x^2 + a1 x) / (b2 x^2 + b1 x + b0), 0.6 the pre-exposure cancellation
ACES = (0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14)
# radiance above which ACES is 1 after the clamp (tm(x) > 1 for x > 8.2): a bound before x^2 keeps
# float64 finite for any finite input without changing a value
_ACES_INPUT_BOUND = 1.0e30
_RGB_TO_XYZ = np.array([[10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0],
                        [2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0],
                        [1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0]])
_XYZ_TO_RGB = np.array([[3.241003275, -1.537398934, -0.498615861],
                        [-0.969224334, 1.875930071, 0.041554224],
                        [0.055639423, -0.204011202, 1.057148933]])
_ILLUMINANT = np.array([0.950428545, 1.0, 1.088900371])      # D65 white, l. 106
_INV_ILLUMINANT = np.array([1.052156925, 1.0, 0.918357670])  # l. 107, as written (not 1 / above)
# exposures evaluated together: at most this many pixels times exposures in one array pass
_PIXELS_PER_PASS = 1 << 20


@dataclass(frozen=True, eq=False)
class FlipReference:
    """The reference's side of HDR-FLIP at each of its exposures, for :func:`hdr_flip_map`.

    ``exposures`` (E,) float64, the levels in stops; ``lab`` (E, H, W, 3) the filtered, clamped,
    Hunt-adjusted CIELab of the tone-mapped reference; ``edges`` and ``points`` (E, H, W) its feature
    magnitudes. About 40 bytes per pixel and exposure.
    """

    exposures: np.ndarray
    lab: np.ndarray
    edges: np.ndarray
    points: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.edges.shape[1:]


def exposure_levels(start: float, stop: float) -> np.ndarray:
    """HDR-FLIP's exposures in stops, (n,) float64, computed in float32 as the package does:
    n = max(2, ceil(stop - start)) levels start + i (stop - start) / (n - 1) (l. 2363-2376)."""
    start32, stop32 = np.float32(start), np.float32(stop)
    if not (np.isfinite(start32) and np.isfinite(stop32) and start32 <= stop32):
        raise ValueError(f"HDR-FLIP needs a finite exposure range with start <= stop, got {start}, {stop}")
    count = int(max(2.0, float(np.ceil(np.float32(stop32 - start32)))))
    step = np.float32(np.float32(stop32 - start32) / np.float32(count - 1))
    return np.array([np.float32(start32 + np.float32(i) * step) for i in range(count)], dtype=np.float64)


@functools.lru_cache(maxsize=None)
def _spatial_filters(ppd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """1-D weights (Y, Cx, Cz first Gaussian, Cz second Gaussian) of the separable CSF filters."""
    radius = int(np.ceil(3.0 * np.sqrt(max(_B1 + _B2) / (2.0 * np.pi ** 2)) * ppd))
    x2 = (np.arange(-radius, radius + 1) / ppd) ** 2

    def gaussian(a, b, root=False):
        scale = np.sqrt(a * np.sqrt(np.pi / b)) if root else a * np.sqrt(np.pi / b)
        return scale * np.exp(-np.pi ** 2 * x2 / b)

    y, cx = gaussian(_A1[0], _B1[0]), gaussian(_A1[1], _B1[1])
    cz1, cz2 = gaussian(_A1[2], _B1[2], root=True), gaussian(_A2[2], _B2[2], root=True)
    cz_norm = np.sqrt(cz1.sum() ** 2 + cz2.sum() ** 2)
    return y / y.sum(), cx / cx.sum(), cz1 / cz_norm, cz2 / cz_norm


@functools.lru_cache(maxsize=None)
def _feature_filters(ppd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1-D weights (Gaussian, its first and second derivative) of the edge and point detectors."""
    sd = 0.5 * _W * ppd
    radius = int(np.ceil(3.0 * sd))
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-x * x / (2.0 * sd * sd))
    dg, ddg = -x * g, (x * x / (sd * sd) - 1.0) * g

    def lobes_to_one(w):  # positive weights sum to 1, negative ones to -1
        return np.where(w > 0.0, w / w[w > 0.0].sum(), w / -w[w < 0.0].sum())

    return g / g.sum(), lobes_to_one(dg), lobes_to_one(ddg)


def _filter(values, across, down):
    """Separable correlation of (..., H, W) with ``across`` along W, ``down`` along H, edges clamped."""
    return correlate1d(correlate1d(values, across, axis=-1, mode="nearest"), down, axis=-2, mode="nearest")


def _lab_hunt(rgb):
    """(..., 3) linear RGB in [0, 1] -> CIELab (D65) with a and b scaled by 0.01 L (Hunt)."""
    xyz = (rgb @ _RGB_TO_XYZ.T) * _INV_ILLUMINANT
    delta = 6.0 / 29.0
    f = np.where(xyz > delta ** 3, np.cbrt(xyz), xyz / (3.0 * delta * delta) + 4.0 / 29.0)
    lightness = 116.0 * f[..., 1] - 16.0
    return np.stack([lightness, 0.01 * lightness * 500.0 * (f[..., 0] - f[..., 1]),
                     0.01 * lightness * 200.0 * (f[..., 1] - f[..., 2])], axis=-1)


@functools.lru_cache(maxsize=None)
def _colour_distance_bounds() -> tuple[float, float]:
    """(c_max, p_c c_max): the q_c-th power of the Hunt-adjusted HyAB distance of green to blue."""
    green, blue = _lab_hunt(np.array([0.0, 1.0, 0.0])), _lab_hunt(np.array([0.0, 0.0, 1.0]))
    c_max = float((abs(green[0] - blue[0]) + np.hypot(green[1] - blue[1], green[2] - blue[2])) ** _QC)
    return c_max, _PC * c_max


def _tone_mapped(hdr, exposures):
    """(E, H, W, 3): ``hdr`` (H, W, 3) scaled by 2^e for each exposure e, FLIP's ACES, clamped to [0, 1]."""
    a2, a1, b2, b1, b0 = ACES
    x = np.minimum(hdr[None] * np.exp2(exposures)[:, None, None, None], _ACES_INPUT_BOUND)
    return np.clip((a2 * x * x + a1 * x) / (b2 * x * x + b1 * x + b0), 0.0, 1.0)


def _ldr_side(ldr, ppd):
    """One image's side of LDR-FLIP: ``(lab (E, H, W, 3), edges (E, H, W), points (E, H, W))``
    of tone-mapped linear RGB ``ldr`` (E, H, W, 3) (steps 1-4 of the module, per image)."""
    xyz = (ldr @ _RGB_TO_XYZ.T) * _INV_ILLUMINANT
    y = 116.0 * xyz[..., 1] - 16.0
    cx, cz = 500.0 * (xyz[..., 0] - xyz[..., 1]), 200.0 * (xyz[..., 1] - xyz[..., 2])
    w_y, w_cx, w_cz1, w_cz2 = _spatial_filters(ppd)
    y_f = (_filter(y, w_y, w_y) + 16.0) / 116.0
    cx_f = _filter(cx, w_cx, w_cx)
    cz_f = _filter(cz, w_cz1, w_cz1) + _filter(cz, w_cz2, w_cz2)
    xyz_f = np.stack([(y_f + cx_f / 500.0) * _ILLUMINANT[0], y_f, (y_f - cz_f / 200.0) * _ILLUMINANT[2]], axis=-1)
    lab = _lab_hunt(np.clip(xyz_f @ _XYZ_TO_RGB.T, 0.0, 1.0))
    g, dg, ddg = _feature_filters(ppd)
    grey = y / 116.0 + 16.0 / 116.0
    across = correlate1d(grey, g, axis=-1, mode="nearest")
    edges = np.hypot(_filter(grey, dg, g), correlate1d(across, dg, axis=-2, mode="nearest"))
    points = np.hypot(_filter(grey, ddg, g), correlate1d(across, ddg, axis=-2, mode="nearest"))
    return lab, edges, points


def _exposure_passes(exposures, pixels):
    """Slices of the exposures evaluated together (memory: ~_PIXELS_PER_PASS pixels at a time)."""
    step = max(1, _PIXELS_PER_PASS // max(pixels, 1))
    return [slice(i, i + step) for i in range(0, len(exposures), step)]


def prepare_flip_reference(reference, *, start: float, stop: float,
                           ppd: float = PIXELS_PER_DEGREE) -> FlipReference:
    """The reference's side of HDR-FLIP (:class:`FlipReference`) over the exposure range
    [``start``, ``stop``] in stops (:func:`exposure_levels`). ``reference`` (H, W, 3): finite,
    non-negative linear radiance (the caller validates and clamps)."""
    reference = np.asarray(reference, dtype=np.float64)
    exposures = exposure_levels(start, stop)
    sides = [_ldr_side(_tone_mapped(reference, exposures[part]), ppd)
             for part in _exposure_passes(exposures, reference.shape[0] * reference.shape[1])]
    lab, edges, points = (np.concatenate(parts) for parts in zip(*sides))
    return FlipReference(exposures=exposures, lab=lab, edges=edges, points=points)


def hdr_flip_map(image, reference: FlipReference, *, ppd: float = PIXELS_PER_DEGREE) -> np.ndarray:
    """Per-pixel HDR-FLIP of ``image`` (H, W, 3; finite, non-negative linear radiance) against the
    prepared ``reference``: (H, W) float64 in [0, 1], the maximum over exposures of
    colour^(1 - feature) (steps 3-5 of the module). Identical images give exactly 0."""
    image = np.asarray(image, dtype=np.float64)
    if image.shape != (*reference.shape, 3):
        raise ValueError(f"image shape {image.shape} differs from the prepared reference's {(*reference.shape, 3)}")
    c_max, pc_max = _colour_distance_bounds()
    error = np.zeros(reference.shape)
    for part in _exposure_passes(reference.exposures, image.shape[0] * image.shape[1]):
        lab, edges, points = _ldr_side(_tone_mapped(image, reference.exposures[part]), ppd)
        lab_r = reference.lab[part]
        colour = (np.abs(lab_r[..., 0] - lab[..., 0])
                  + np.hypot(lab_r[..., 1] - lab[..., 1], lab_r[..., 2] - lab[..., 2])) ** _QC
        colour = np.where(colour < pc_max, colour * (_PT / pc_max),
                          _PT + (colour - pc_max) / (c_max - pc_max) * (1.0 - _PT))
        feature = (np.maximum(np.abs(reference.edges[part] - edges), np.abs(reference.points[part] - points))
                   / np.sqrt(2.0)) ** _QF
        np.maximum(error, np.max(colour ** (1.0 - feature), axis=0), out=error)
    return error
