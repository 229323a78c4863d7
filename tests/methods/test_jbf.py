"""The JBF base denoiser (methods/jbf.py): its default constants are the ones docs/methods.md
records as chosen on training scenes (tools/jbf_constants.py), and with them denoise_image is the
documented kernel, checked against a brute-force loop written from the docstring's formula."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import numpy as np

from mcbench.io.buffers import ImageBuffers
from methods import jbf

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("radius", "sigma_spatial", "sigma_color", "sigma_albedo", "sigma_normal", "sigma_depth")


def documented_constants() -> dict:
    """The ``chosen: {...}`` line of the JBF paragraph of docs/methods.md (the output of
    tools/jbf_constants.py recorded there)."""
    text = (ROOT / "docs" / "methods.md").read_text()
    paragraph = text[text.index("* **JBF**"):]
    match = re.search(r"chosen: (\{[^}]*\})", paragraph)
    assert match, "docs/methods.md: the JBF paragraph records no 'chosen: {...}' line"
    return ast.literal_eval(match.group(1))


def test_defaults_are_the_documented_constants():
    documented = documented_constants()
    assert set(documented) == set(NAMES)
    for function in (jbf.denoise, jbf.denoise_image):
        defaults = {name: inspect.signature(function).parameters[name].default for name in NAMES}
        assert defaults == documented, function.__name__


def brute_force_jbf(color, variance, albedo, normal, depth, *, radius, sigma_spatial, sigma_color,
                    sigma_albedo, sigma_normal, sigma_depth):
    """The module docstring's kernel, pixel by pixel in float64, the window clipped at the
    borders: exp(-|p-q|^2/2 ss^2) exp(-D^2/2 sc^2) exp(-|a_p-a_q|^2/2 sa^2) exp(-|n_p-n_q|^2/2 sn^2)
    exp(-(d_p-d_q)^2/2 sd^2), D^2 the mean over channels of (x_p-x_q)^2/(Var x_p + Var x_q),
    depth divided by the median depth of the pixels with depth > 0."""
    h, w, _ = color.shape
    d = depth / np.median(depth[depth > 0])
    out = np.zeros_like(color)
    for y in range(h):
        for x in range(w):
            acc, total = np.zeros(3), 0.0
            for qy in range(max(0, y - radius), min(h, y + radius + 1)):
                for qx in range(max(0, x - radius), min(w, x + radius + 1)):
                    d2 = np.mean((color[y, x] - color[qy, qx]) ** 2 / (variance[y, x] + variance[qy, qx]))
                    k = (np.exp(-((qy - y) ** 2 + (qx - x) ** 2) / (2 * sigma_spatial ** 2))
                         * np.exp(-d2 / (2 * sigma_color ** 2))
                         * np.exp(-np.sum((albedo[y, x] - albedo[qy, qx]) ** 2) / (2 * sigma_albedo ** 2))
                         * np.exp(-np.sum((normal[y, x] - normal[qy, qx]) ** 2) / (2 * sigma_normal ** 2))
                         * np.exp(-(d[y, x] - d[qy, qx]) ** 2 / (2 * sigma_depth ** 2)))
                    acc += k * color[qy, qx]
                    total += k
            out[y, x] = acc / total
    return out


def test_default_kernel_equals_the_brute_force_formula():
    rng = np.random.default_rng(3)
    h, w = 9, 8
    color = rng.uniform(0.1, 1.0, (h, w, 3))
    variance = rng.uniform(0.01, 0.1, (h, w, 3))
    albedo = rng.uniform(0, 1, (h, w, 3))
    albedo[:, :4] = 0.3                                   # an albedo edge
    normal = rng.normal(size=(h, w, 3))
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    normal[:, :4] = (0.0, 0.0, 1.0)
    depth = rng.uniform(1.0, 3.0, (h, w))
    depth[0, 0] = 0.0                                     # a miss: not in the median
    image = ImageBuffers(color=color, variance=variance, albedo=albedo, normal=normal, depth=depth, spp=4)
    got = jbf.denoise_image(image)
    want = brute_force_jbf(color, variance, albedo, normal, depth, **documented_constants())
    assert got.dtype == np.float32 and got.shape == (h, w, 3)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
