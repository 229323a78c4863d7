"""The ensemble against golden outputs of the authors' public C++ program (LuisaGroup/
Ensemble-Denoising; tests/data/golden/ensemble_cpp/README.md says how they were made).

With the switches that turn our documented departures into the program's behaviour -- the exact
solver (the program's ``fbstab`` reaches the same optimum), the filter options of
``PUBLIC_CODE_FILTER`` (guide-variance blur with OpenCV's 9-tap kernel, the code's outlier pass,
reflected windows, the standardised normal, Eq. 33 summed and floored at 1e-6) and
``public_code_sigmas`` (its feature terms divide by sigma) -- ``methods.ensemble.combine`` gives the
program's outputs to float32 rounding. Tolerances (measured maxima in brackets, 4 cases):

* raw blend z and final blend: relMSE <= 1e-12 [3.6e-15]. Both programs store float32 images
  (relative rounding 6e-8, so a relMSE of ~1e-15); fbstab stops at an absolute tolerance of
  1e-10 on objectives of ~1e-2 .. 1e6 at this exposure.
* guide variance Var[z] after the 9 x 9 blur: max |ours - C++| <= 1e-5 x its maximum [2.4e-7]:
  a squared difference of two float32 blends.
* filtered weights, divided by their per-pixel sum as the program's blend does: max |ours - C++|
  <= 1e-4 [9.8e-6]: the program filters in float32 and its outlier statistics are float32 sums;
  a pixel whose outlier decision flipped would differ by ~1e-2 or more.

Each switch set back to our default, or a wrong constant, moves at least one output far beyond
its tolerance (``test_each_departure_is_seen``): the comparison has power.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import methods.ensemble as E
from mcbench.combine.blending import combine_with
from mcbench.combine.weight_filter import PUBLIC_CODE_FILTER, public_code_sigmas
from mcbench.filters.blur_and_outliers import gaussian_blur
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.case_folders import RENDER_FILES, denoiser_files, read_image

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden" / "ensemble_cpp"
CASES = sorted(p.name for p in GOLDEN.iterdir() if p.is_dir()) if GOLDEN.is_dir() else []
BASES = ("nfor", "oidn", "rdfc")
#: our combine() with the program's behaviour (the module docstring)
AS_THE_PROGRAM = dict(solver="exact", **PUBLIC_CODE_FILTER, **public_code_sigmas())
RELMSE_TOLERANCE = 1e-12
GUIDE_VARIANCE_TOLERANCE = 1e-5
WEIGHT_TOLERANCE = 1e-4


def load_case(name: str):
    folder = GOLDEN / name
    layers = {layer: read_image(folder / file) for file, layer in RENDER_FILES.items()}
    layers["color"] = 0.5 * (layers["color_a"] + layers["color_b"])
    buffers = RenderBuffers(layers=layers, spp=0, source=str(folder))
    inputs = []
    for d in BASES:
        files = denoiser_files(folder, d)
        inputs.append(Denoised(full=read_image(files["full"]), a=read_image(files["a"]), b=read_image(files["b"]),
                               source=str(files["full"])))
    golden = {"raw": read_image(folder / "out" / "blend-raw.exr"), "blend": read_image(folder / "out" / "blend.exr"),
              "guide_variance": read_image(folder / "guide-var.exr"),
              "weights": np.stack([read_image(folder / "out" / f"weight-{d}-filtered.exr") for d in BASES])}
    return buffers, inputs, golden


def relmse(image, reference) -> float:
    image, reference = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    return float(np.mean((image - reference) ** 2 / (reference ** 2 + 1e-2)))


def errors(buffers, inputs, golden, **options) -> dict[str, float]:
    """Each output of our combine() with ``options`` against the program's: relMSE of the raw and
    final blends, the guide variance's max error relative to its maximum, the normalised filtered
    weights' max error."""
    out = E.combine(buffers, inputs, **options)
    n = len(inputs)
    y = {k: np.stack([np.asarray(d.image(k), np.float64) for d in inputs]) for k in ("full", "a", "b")}
    raw = np.stack([out.extras[f"weights_raw_{i}"] for i in range(n)]).astype(np.float64)
    variance = gaussian_blur(0.5 * (combine_with(raw, y["a"]) - combine_with(raw, y["b"])) ** 2, kernel_size=9)
    theirs = np.clip(golden["weights"].astype(np.float64), -1.0, 2.0)     # blend.h: clamp, / sum
    theirs /= theirs.sum(axis=0)
    ours = np.stack([out.extras[f"weights_filtered_{i}"] for i in range(n)]).astype(np.float64)
    return {"raw": relmse(combine_with(raw, y["full"]), golden["raw"]),
            "blend": relmse(out.full, golden["blend"]),
            "guide_variance": float(np.abs(variance - golden["guide_variance"]).max()
                                    / golden["guide_variance"].max()),
            "weights": float(np.abs(ours - theirs).max())}


TOLERANCES = {"raw": RELMSE_TOLERANCE, "blend": RELMSE_TOLERANCE, "guide_variance": GUIDE_VARIANCE_TOLERANCE,
              "weights": WEIGHT_TOLERANCE}


def test_golden_cases_are_present():
    assert CASES == ["cornell_box_spp64", "cornell_box_spp8", "fine_textures_spp64", "fine_textures_spp8"]


@pytest.mark.parametrize("case", CASES)
def test_ensemble_equals_the_authors_program(case):
    buffers, inputs, golden = load_case(case)
    got = errors(buffers, inputs, golden, **AS_THE_PROGRAM)
    for key, tolerance in TOLERANCES.items():
        assert got[key] <= tolerance, (key, got[key])


#: every departure of our defaults or readings from the program, and wrong constants: each must be
#: seen by the comparison (the blend or the weights beyond their tolerance)
DEPARTURES = {
    "iterative solver (the paper's; the program ran fbstab)": dict(solver="iterative"),
    "iterative solver with away steps (our switch)": dict(solver="iterative", away_steps=True),
    "guide variance not blurred": dict(guide_variance_blur="none"),
    "our outlier pass (value -> neighbours' mean)": dict(outlier_removal="neighbour_mean"),
    "no outlier pass": dict(outlier_removal="none"),
    "windows clipped at the borders": dict(filter_border="clip"),
    "normal as rendered (not standardised)": dict(normal_features="raw"),
    "Eq. 33 averaged over the channels": dict(colour_distance="mean"),
    "feature terms over 2 sigma^2 (the text)": dict(sigma_albedo=0.25, sigma_normal=0.15),
    "wrong constant: sigma_z 2.2": dict(sigma_color=2.2),
    "wrong constant: radius 6": dict(radius=6),
}


@pytest.mark.parametrize("departure", list(DEPARTURES))
def test_each_departure_is_seen(departure):
    """Some case shows the departure beyond the tolerances (not every case needs to: e.g. the
    border rule is invisible where the border pixels' kernels are flat)."""
    seen = []
    for case in CASES:
        buffers, inputs, golden = load_case(case)
        got = errors(buffers, inputs, golden, **{**AS_THE_PROGRAM, **DEPARTURES[departure]})
        seen.append(got["blend"] > RELMSE_TOLERANCE or got["weights"] > WEIGHT_TOLERANCE)
    assert any(seen), departure
