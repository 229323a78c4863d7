"""One-hot selection among the combiner's inputs by estimated MSE (Zheng et al. 2021
Sec. 5.2.6, the comparison method of their Tables 1-2; NFOR's bandwidth selection, Bitterli et
al. 2016 Sec. 5.3). The functions live in :mod:`mcbench.combine.selection`; see its docstring for the
equations.

Per pixel and channel (channel-wise, like the ensemble's weights and NFOR's selection map) the
input with the lowest estimated MSE is selected; ties go to the first input. MSE estimates
(Eq. 36-37): MSE[y_i^A] ~ (y_i^A - x^B)^2 - Var[x^B] with Var[x^B] the render's ``variance_b``
(variance of the mean), likewise B, and MSE[y_i] ~ (MSE[y_i^A] + MSE[y_i^B]) / 2 - Var[y_i] with
Var[y_i] ~ (y_i^A - y_i^B)^2 / 4 (as NFOR).

Results for full, A and B: the full result selects among the inputs' full results with the
full-buffer map MSE[y_i] (Eq. 37); A selects among their A results with A's own half-buffer map
MSE[y_i^A] (Eq. 36, A's result against x^B) and B likewise. (The ensemble instead applies one set
of weights, solved from both halves, to all three images; here each image gets the selection its
own estimate gives, as Eq. 36 defines one per half.)

``prefilter`` chooses the variant:

* ``"none"``: raw MSE maps, raw one-hot maps (unfiltered; not in the paper).
* ``"sbf"``: the MSE maps are pre-filtered by SBF's cross-bilateral filter (Li et al. 2012)
  guided by the noisy full colour (variance-normalised, Eq. 33), albedo and normal, with the
  Sec. 4.2 numbers (radius 7, sigma_s 3, sigma_z 2, sigma_albedo 0.25, sigma_normal 0.15): the
  papers give none for this use, so that is our choice (``mcbench.combine.selection.SBF_MSE_FILTER``).
* ``"nfor"``: the MSE maps are pre-filtered by NFOR's NL-means (guide: noisy full colour and its
  variance; 19 x 19 window, 3 x 3 patches, k = 1; ``mcbench.combine.selection.NFOR_MSE_FILTER``).
* ``"post"``: raw MSE maps, and the one-hot maps are filtered by the ensemble's Sec. 4.2
  cross-bilateral weight filter (guided by the raw combined images z, z^A, z^B of that image's
  selection, Var[z] ~ (z^A - z^B)^2 / 2, albedo, normal; the paper's parameters), then blended
  with the filtered (soft) maps.

Every map guide uses the full-buffer colour and features for all three images.
``extras``: ``weights_raw_{i}`` (the one-hot map of input i) and ``weights_filtered_{i}`` (what
was blended: equal to the raw map except for ``"post"``), both (H, W, 3) float32, for the full
image, so the viewer shows them like the ensemble's weights.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from mcbench.combine import selection as sel
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.contracts.method import MethodSpec

PREFILTERS = ("none", "sbf", "nfor", "post")
IMAGES = ("full", "a", "b")


def combine(buffers: RenderBuffers, inputs: list[Denoised], *,
            prefilter: Literal["none", "sbf", "nfor", "post"] = "none") -> Denoised:
    """Select per pixel-channel the input of lowest estimated MSE (see the module docstring).

    Returns Denoised(full, a, b, extras) with float32 (H, W, 3) images and the full image's
    selection maps in ``extras``. Raises ValueError for no inputs, an unknown ``prefilter`` or
    NaN/Inf in the render's half buffers or the inputs.
    """
    if not inputs:
        raise ValueError("one_hot needs at least one input")
    if prefilter not in PREFILTERS:
        raise ValueError(f"one_hot: unknown prefilter {prefilter!r}; choose one of {PREFILTERS}")
    layers = {name: np.asarray(buffers.layers[name], np.float64) for name in
              ("color", "variance", "color_a", "color_b", "variance_a", "variance_b", "albedo", "normal")}
    results = {which: np.stack([np.asarray(d.image(which), np.float64) for d in inputs]) for which in IMAGES}
    if results["full"].shape[1:] != layers["color"].shape:
        raise ValueError(f"one_hot: input images {results['full'].shape[1:]} differ from the render's "
                         f"{layers['color'].shape} ({buffers.source})")
    sel.check_finite_arrays({**{f"{buffers.source}: {name}": layers[name] for name in layers},
                             **{f"inputs' {which} images": results[which] for which in IMAGES}},
                            what="one_hot")
    mse = sel.estimate_mse_maps(layers["color_a"], layers["color_b"], layers["variance_a"],
                                layers["variance_b"], results["a"], results["b"])
    maps = [mse[which] for which in IMAGES]
    if prefilter == "nfor":
        maps = sel.prefilter_mse_nl_means(maps, layers["color"], layers["variance"])
    elif prefilter == "sbf":
        maps = sel.prefilter_mse_bilateral(maps, layers["color"], layers["variance"],
                                           layers["albedo"], layers["normal"])
    raw = {which: sel.one_hot_selection(m) for which, m in zip(IMAGES, maps)}
    if prefilter == "post":
        weights = {which: sel.filter_selection_maps(raw[which], results["full"], results["a"],
                                                    results["b"], layers["albedo"], layers["normal"])
                   for which in IMAGES}
    else:
        weights = raw
    extras = {f"weights_raw_{i}": raw["full"][i].astype(np.float32) for i in range(len(inputs))}
    extras.update({f"weights_filtered_{i}": weights["full"][i].astype(np.float32) for i in range(len(inputs))})
    out = {which: sel.blend(weights[which], results[which]).astype(np.float32) for which in IMAGES}
    return Denoised(full=out["full"], a=out["a"], b=out["b"], extras=extras)


METHOD = MethodSpec(kind="combiner", label="One-hot selection", run=combine, comparison_role="one-hot selection")
