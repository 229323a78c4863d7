"""RDFC: Robust Denoising using Feature and Color information (Rousselle, Manzi and Zwicker,
Computer Graphics Forum 32(7), Pacific Graphics 2013), base denoiser #8 of Zheng et al. 2021.

Runs as the authors' code runs it: fbksd/fbksd-package ``denoisers/RDFC/src/`` at commit
3059e1480bf7d0eb5cd4a8a106e37fc06078c59f (``M`` = main.cpp, ``F`` = multifilm.cpp, ``C`` =
featurefilter.cu; file:line). The filter steps live in :mod:`mcbench.filters.rdfc_filter`; the
table step by step, the departures and their measured effects are in docs/fidelity_rdfc.md.

The two half buffers A and B play the authors' two sample buffers (M:49-54: the first spp/2
samples of a pixel go to buffer 0, the rest to buffer 1). One ``denoise``:

1. **Features** (F:107-123): normal mapped to (n + 1) / 2, albedo divided by max(1, max channel),
   world position through the XYZ->sRGB matrix (F:117-119), visibility (1 channel). The
   authors' fifth feature, "caustic", is the constant {1, 1, 1} (F:113): zero distance and zero
   variance, so its weight is always 1 and it is left out. Each is **prefiltered** (F:300-359,
   C:854-871): NL-means of its two buffers with shared weights, window 5, patch 3, k = 1, weight box
   2, guide = the buffers' mean with the rescaled variance (C:933-960,1392-1412) of the renderer's
   ``*_variance`` (variance of the full mean, transformed like the feature); the feature is then
   the mean of the two filtered buffers and its variance (A~ - B~)^2 / 4 pyramid-smoothed
   (C:869-870,1415-1429).
2. **Colour**: guide y = (A + B) / 2 with the rescaled variance V = V_full * box21((A-B)^2/4) /
   (1e-10 + box21(V_full)) (F:717-723), used by every colour distance and by SURE.
3. **Candidates** (F:688-756), all with window ``radius``: FIRST (k_c 0.45, patch 1), SECOND (0.45,
   patch 3), THIRD (features only, C:1046-1048), k_f = 0.6; feature tau 1e-3 for FIRST/SECOND and
   1e-4 for THIRD (F:700), position tau maxPos^2 * tau (F:328-333,731). A and B are filtered with
   weights from y (C:68-89). dF/dy: finite difference with 1.01 (FIRST/SECOND) or w_max / sum w
   (THIRD), clamped (C:1335-1370).
4. **SURE** per candidate, channel mean (F:427-434,639), y = full mean, sigma^2 = V.
5. **Selection** (F:631-685): SURE maps NL-means filtered (window 1, patch 3, k 1, weight box 2,
   colour guide y, V), argmin rule of F:653-661 (with the authors' index bug, see
   :func:`mcbench.filters.rdfc_filter.select_candidate`), binary maps filtered (window 5, same
   otherwise), blend of A~ and B~ (F:581-628).
6. **Second pass** (F:409-423): the blended A~, B~ filtered again with shared weights from their
   mean, variance (A~ - B~)^2 / 4 pyramid-smoothed (C:900-916), window radius // 2 (F:410; 0, an
   empty window, for radius 1), patch 3, k_c
   0.45, k_f 0.6, weight box 2, ``use_diff_var=false`` (2 Vd_p denominators), tau 1e-4.

Output: ``Denoised(full = (A~~ + B~~) / 2, a = A~~, b = B~~)`` (C:1318-1321; the ensemble reads the
co-filtered halves).

Switches (keyword-only; defaults are the authors'):

* ``radius`` = 10: the authors' README for their pbrt scenes ("wnd_rad [10]",
  denoisers/RDFC/README.txt); fbksd's driver uses 20 (M:31): ``radius=20``.
* ``variance="rescaled"``; ``"raw"`` uses the renderer's per-pixel variance of the full mean
  unscaled (the authors' own branch for random samples, F:227-228,716-721 ``use_ld_samples``
  false).
* ``clamp_derivative=True`` (C:1354-1369); False keeps the finite difference unclamped.
* ``index_bug=True`` (F:656); False compares with SECOND's own derivative, as the code evidently
  intends (``derivatives[0][3*pix]`` on the other side of the same comparison).
* ``symmetric_weights=True`` (C:479-491,620-626: the symmetric weight blended in where both
  distances are below ``MAX_D2`` = 25, C:19); False turns the blend off in every NL-means call
  (prefilter, candidates, error and selection filters, second pass): each neighbour keeps
  exp(-max(0, d)). A diagnostic switch, not a departure the default takes: on cornell_box the blend
  lets THIRD average the directly visible light into the ceiling (docs/fidelity_rdfc.md, "Known
  failure").
* ``nonfinite="authors"``: NaN/inf in the render layers are left as they are, but for a NaN in the
  normal layers, which becomes 0 after the (n + 1) / 2 map with variance 0 (the authors skip NaN
  normal samples, F:135-138,160-164, and guard nothing else); the output is not sanitised either.
  ``"zero"``: ``np.nan_to_num`` on every layer read and on the output, which keeps the output finite for a broken input. Renders reaching the pipeline are
  finite (``mcbench.render.renderer`` raises on NaN/inf in any pass), where both agree exactly.

Departures without a switch (each with its reason; docs/fidelity_rdfc.md):

* Features per pixel, not per sample (the renderer writes pixel means): exact for the normal map
  and the position matrix (affine); the albedo division by max(1, max channel) acts on each
  buffer's mean (the same wherever every sample's albedo is <= 1). Feature variances are the
  renderer's ``*_variance`` mapped through the same transforms (the position's without the
  components' covariance, which is not rendered). Visibility is the renderer's fraction of samples
  whose one-sample direct light R = f W is positive in the red channel, as theirs,
  ``sample[DIRECT_R] > 0.f`` (F:123; ``mcbench.render.visibility.direct_light_visible``).
* ``GetScaledSampleVariance`` box-filters with a hard-coded 3-channel stride (C:1406-1409), which
  for the 1-channel visibility reads other pixels and memory left from earlier kernels; we box the
  one channel (stale memory cannot be reproduced).
* float64 throughout (theirs float32); window neighbours mirrored as C:40-41 and then clipped into
  the image, which only matters for windows wider than the image (their index leaves the buffer).
"""

from __future__ import annotations

import numpy as np

from mcbench.filters.rdfc_filter import (MAX_D2, Feature, clamp_derivative as clamp_rule, dual_buffer_variance,
                                         finite_difference_derivative, nl_means, scaled_sample_variance,
                                         select_candidate, sure)
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.contracts.method import MethodSpec
from mcbench.progress import StageLog

WINDOW_RADIUS = 10                       # README "wnd_rad [10]"; fbksd M:31 uses 20
K_COLOR = 0.45                           # F:696
K_FEATURE = 0.6                          # F:697
CANDIDATES = (                           # F:696-700: (name, k_c or None = features only, patch, tau)
    ("FIRST", K_COLOR, 1, 1e-3),
    ("SECOND", K_COLOR, 3, 1e-3),
    ("THIRD", None, 3, 1e-4),
)
PREFILTER = dict(radius=5, patch_radius=3, weight_radius=2, k=1.0)          # F:302-305, C:1029
ERROR_FILTER = dict(radius=1, patch_radius=3, weight_radius=2, k=1.0)       # F:642-646
SELECTION_FILTER = dict(radius=5, patch_radius=3, weight_radius=2, k=1.0)   # F:674-676
SECOND_PASS = dict(patch_radius=3, weight_radius=2, k=K_COLOR, use_diff_var=False)  # F:410-415
TAU_SECOND = 1e-4                        # F:416-420
#: XYZ -> linear sRGB, applied by the authors to the world position (F:117-119)
XYZ_TO_RGB = np.array([[3.240479, -1.537150, -0.498535],
                       [-0.969256, 1.875991, 0.041556],
                       [0.055648, -0.204043, 1.057311]])
FEATURES = ("normal", "albedo", "position", "visibility")
RENDER_LAYERS = ("color_a", "color_b", "variance",
                 *(f"{name}{s}" for name in FEATURES for s in ("_a", "_b", "_variance")))


NONFINITE = ("authors", "zero")


def _layer(buffers: RenderBuffers, name: str, nonfinite: str = "authors") -> np.ndarray:
    """Render layer ``name`` as float64 (H, W, C) (a 1-channel layer gets its channel axis).
    ``nonfinite="authors"`` leaves NaN/inf as they are (the authors' code has no guard but for NaN
    normals, see :func:`authors_features`); ``"zero"`` applies ``np.nan_to_num`` (NaN -> 0,
    +-inf -> +-float max)."""
    if name not in buffers.layers:
        raise ValueError(f"{buffers.source}: RDFC reads the render layer {name!r}, which this render lacks; "
                         f"re-render with a renderer that writes {', '.join(RENDER_LAYERS)}")
    a = np.asarray(buffers.layers[name], dtype=np.float64)
    if nonfinite == "zero":
        a = np.nan_to_num(a)
    return a[..., None] if a.ndim == 2 else a


def authors_features(buffers: RenderBuffers, *, nonfinite: str = "authors"):
    """The four features of the authors' code (F:107-136), each as (A, B, variance of the full mean)
    (H, W, C) float64, and maxPos (F:328-333).

    Per sample in theirs, per pixel here: the normal map (n+1)/2 is affine, so the pixel mean is
    the same; albedo / max(1, max channel) is applied to each buffer's mean (equal where the
    albedo of every sample is <= 1, Mitsuba's diffuse reflectance); the XYZ->sRGB matrix is linear.
    Variances follow the maps: /4 for the normal, /m^2 (m of the full mean) for the albedo,
    sum_j M_ij^2 Var_j for the position (the components' covariance is not rendered).

    Non-finite values (``nonfinite``, see :func:`denoise`): the authors skip a NaN normal component
    of a sample (F:135-138,160-164) and guard nothing else. Per pixel, a NaN in the normal layers
    becomes 0 *after* the map (the authors' buffer and M2 keep their zero initialisation, F:79, when
    every sample of the pixel is skipped) and its variance 0; every other layer keeps its NaN/inf.
    ``"zero"``: ``np.nan_to_num`` on every layer before the maps (a NaN normal then maps to 0.5)."""
    out = {}
    for name in FEATURES:
        a, b = _layer(buffers, name + "_a", nonfinite), _layer(buffers, name + "_b", nonfinite)
        var = np.maximum(_layer(buffers, name + "_variance", nonfinite), 0.0)
        if name == "normal":
            a, b, var = (a + 1.0) / 2.0, (b + 1.0) / 2.0, var / 4.0
            if nonfinite == "authors":
                a, b, var = (np.where(np.isnan(x), 0.0, x) for x in (a, b, var))
        elif name == "albedo":
            ma = np.maximum(1.0, a.max(axis=-1, keepdims=True))
            mb = np.maximum(1.0, b.max(axis=-1, keepdims=True))
            m = np.maximum(1.0, ((a + b) / 2.0).max(axis=-1, keepdims=True))
            a, b, var = a / ma, b / mb, var / m ** 2
        elif name == "position":
            a, b = a @ XYZ_TO_RGB.T, b @ XYZ_TO_RGB.T
            var = var @ (XYZ_TO_RGB ** 2).T
        out[name] = (a, b, var)
    pos = (out["position"][0] + out["position"][1]) / 2.0
    finite = pos[np.isfinite(pos)]
    max_pos = max(0.0, float(finite.max())) if finite.size else 0.0
    return out, max_pos


def prefilter_features(features: dict, *, max_d2: float = MAX_D2):
    """F:300-359 / C:854-871: each feature's two buffers NL-means filtered with shared weights
    (``PREFILTER``; guide = their mean, variance = :func:`scaled_sample_variance` of the feature's
    sample variance; ``max_d2``: :func:`nl_means`'s symmetric-blend threshold); returns {name: (mean of the filtered buffers, (A~ - B~)^2/4 pyramid-smoothed)}."""
    out = {}
    for name, (a, b, var) in features.items():
        guide_var = scaled_sample_variance(a, b, var)
        filt = nl_means(np.stack([a, b]), (a + b) / 2.0, guide_var, max_d2=max_d2, **PREFILTER).buffers
        out[name] = ((filt[0] + filt[1]) / 2.0, dual_buffer_variance(filt[0], filt[1]))
    return out


def feature_set(prefiltered: dict, tau: float, max_pos: float) -> list[Feature]:
    """The features with threshold ``tau`` (position: maxPos^2 tau, F:340,418,731)."""
    return [Feature(value, var, tau * max_pos ** 2 if name == "position" else tau)
            for name, (value, var) in prefiltered.items()]


def candidates(a, b, y, v, prefiltered, max_pos, *, radius: int, clamp: bool = True, max_d2: float = MAX_D2):
    """The three candidates (F:688-756) of buffers A, B: returns lists (one per candidate) of the
    filtered buffers (2, H, W, 3), the filtered mean (H, W, 3) and dF/dy (H, W, 3). FIRST and SECOND
    (FilterDataDelta, C:1181-1237) differ only in the patch radius and run as one kernel call."""
    (_, k_c, patch1, tau1), (_, k_c2, patch2, tau2), (_, k_third, patch3, tau3) = CANDIDATES
    if k_c != k_c2 or tau1 != tau2 or k_third is not None:
        raise ValueError("FIRST and SECOND must share k_c and tau, THIRD be features only (CANDIDATES)")
    both = np.stack([a, b])
    results = nl_means(both, y, v, radius=radius, patch_radius=(patch1, patch2), weight_radius=0, k=k_c,
                       features=feature_set(prefiltered, tau1, max_pos), feature_k=K_FEATURE, delta=True,
                       max_d2=max_d2)
    derivs = [finite_difference_derivative(res.buffers.mean(axis=0), res.scaled, y) for res in results]
    # THIRD: feat_only, FilterData with weight box 0 (C:1046-1048); dF/dy = w_max / sum w (C:1343-1346)
    third = nl_means(both, y, v, radius=radius, patch_radius=patch3, weight_radius=0, k=1.0, use_colour=False,
                     features=feature_set(prefiltered, tau3, max_pos), feature_k=K_FEATURE, max_d2=max_d2)
    results.append(third)
    derivs.append(np.repeat(third.centre[..., None], 3, axis=-1))
    if clamp:
        derivs = [clamp_rule(d, res.centre) for d, res in zip(derivs, results)]
    return [res.buffers for res in results], [res.buffers.mean(axis=0) for res in results], derivs


def select_and_blend(bufs, means, derivs, y, v, *, index_bug: bool = True, max_d2: float = MAX_D2):
    """F:631-685 and F:581-628: SURE maps filtered (``ERROR_FILTER``), the argmin rule, binary maps
    filtered (``SELECTION_FILTER``), blend. Returns the blended buffers (2, H, W, 3) and the
    selection weights (H, W, K)."""
    errors = np.stack([sure(m, d, y, v) for m, d in zip(means, derivs)])            # (K, H, W)
    err_f = nl_means(errors[..., None], y, v, max_d2=max_d2, **ERROR_FILTER).buffers[..., 0]
    sel = select_candidate(err_f, derivs[0], derivs[1], index_bug=index_bug)
    onehot = np.stack([(sel == i).astype(np.float64) for i in range(len(means))])
    weights = nl_means(onehot[..., None], y, v, max_d2=max_d2, **SELECTION_FILTER).buffers[..., 0]   # (K, H, W)
    acc = np.maximum(weights.sum(axis=0), 1e-300)
    blend = np.einsum("khw,kbhwc->bhwc", weights, np.stack(bufs)) / acc[None, :, :, None]
    return blend, np.moveaxis(weights / acc, 0, -1)


def second_pass(blend, prefiltered, max_pos, *, radius: int, max_d2: float = MAX_D2):
    """F:409-423: the two pass-1 buffers filtered again with shared weights (``SECOND_PASS``),
    guide = their mean, variance :func:`dual_buffer_variance` (C:900-916), window ``radius // 2``
    (``wnd_rad / 2``, F:410: 0 for ``radius=1``, an empty window whose output is the input,
    C:1150-1153,1175-1177); (2, H, W, 3)."""
    guide_var = dual_buffer_variance(blend[0], blend[1])
    return nl_means(blend, blend.mean(axis=0), guide_var, radius=radius // 2,
                    features=feature_set(prefiltered, TAU_SECOND, max_pos), feature_k=K_FEATURE,
                    max_d2=max_d2, **SECOND_PASS).buffers


def denoise(buffers: RenderBuffers, *, radius: int = WINDOW_RADIUS, variance: str = "rescaled",
            clamp_derivative: bool = True, index_bug: bool = True, symmetric_weights: bool = True,
            nonfinite: str = "authors"):
    """RDFC as the authors' code runs it (module docstring); returns Denoised(full, a, b) float32
    (H, W, 3). Keyword switches: module docstring."""
    if variance not in ("rescaled", "raw"):
        raise ValueError(f"variance must be 'rescaled' (the authors') or 'raw', got {variance!r}")
    if nonfinite not in NONFINITE:
        raise ValueError(f"nonfinite must be 'authors' (the authors' handling) or 'zero', got {nonfinite!r}")
    if int(radius) < 1:
        raise ValueError(f"radius must be >= 1 (10: the authors' scenes, 20: fbksd), got {radius!r}")
    a, b = _layer(buffers, "color_a", nonfinite), _layer(buffers, "color_b", nonfinite)
    y = (a + b) / 2.0
    v_full = np.maximum(_layer(buffers, "variance", nonfinite), 0.0)
    v = scaled_sample_variance(a, b, v_full) if variance == "rescaled" else v_full
    max_d2 = MAX_D2 if symmetric_weights else -np.inf
    stage_done = StageLog.for_image("rdfc", *y.shape[:2])    # prints on large images only
    features, max_pos = authors_features(buffers, nonfinite=nonfinite)
    prefiltered = prefilter_features(features, max_d2=max_d2)
    stage_done("feature prefiltering")
    bufs, means, derivs = candidates(a, b, y, v, prefiltered, max_pos, radius=int(radius), clamp=clamp_derivative,
                                   max_d2=max_d2)
    stage_done("candidate filters")
    blend, _ = select_and_blend(bufs, means, derivs, y, v, index_bug=index_bug, max_d2=max_d2)
    final = second_pass(blend, prefiltered, max_pos, radius=int(radius), max_d2=max_d2)
    stage_done("selection and second pass")
    if nonfinite == "zero":
        final = np.nan_to_num(final)
    out_a, out_b = final[0].astype(np.float32), final[1].astype(np.float32)
    full = ((out_a.astype(np.float64) + out_b) / 2.0).astype(np.float32)
    return Denoised(full=full, a=out_a, b=out_b)


METHOD = MethodSpec(kind="denoiser", label="#8 RDFC", run=denoise, render_layers=RENDER_LAYERS)
