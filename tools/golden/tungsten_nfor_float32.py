"""How much float32 rounding alone moves NFOR on the golden cases (the golden test's tolerance).

Tungsten computes in float32: its prefiltered features carry rounding noise, and it solves every
weighted least-squares fit with Eigen's column-pivoted QR in float32 on unscaled columns. Ours is
float64. Two measurements per stored case, each printed as the max, median and 99th percentile of
|x - y| / (|y| + 0.01) (the golden test's per-pixel error) and, for the output, the relMSE:

1. ``solve``: the pass-1 regression of half buffer A at k = 0.5 (colour A, guide B with 2 x the
   full variance, features B prefiltered with the Tungsten switches), solved by our float64 solver
   (:func:`methods.nfor.collaborative_regression`) and by a float32 emulation written here from
   the definition (per pixel sqrt(W) X and sqrt(W) Y in float32, LAPACK ``sgeqp3`` column-pivoted
   QR via :func:`scipy.linalg.qr`, pivots |R_kk| <= eps_32 x the largest column norm dropped as
   Eigen does, fit evaluated and accumulated in float32); same float64 weights in both.
2. ``ulp N``: our whole NFOR with :data:`methods.nfor.TUNGSTEN`, against itself with the
   prefiltered features multiplied by (1 + N 2^-24 xi), xi uniform in [-1, 1] (fixed seed), for
   N = 1 and 4: the effect of float32-rounding-sized noise in the features, which Tungsten's
   float32 prefilter produces (a float32 weighted mean of 121 terms is off by a few ulps).

Run::

    . .venv/bin/activate
    python tools/golden/tungsten_nfor_float32.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.linalg

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from mcbench.filters.nlmeans import nl_means_window_weights  # noqa: E402
from mcbench.io.buffers import RenderBuffers  # noqa: E402
from mcbench.io.tungsten_buffers import read_case  # noqa: E402
from methods import nfor  # noqa: E402

GOLDEN = ROOT / "tests" / "data" / "golden" / "tungsten_nfor"


def planes(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.moveaxis(array, 2, 0))


def regression_float32(color, guide, guide_variance, features, k, radius=9, patch=3):
    """The collaborative regression with Tungsten's weights, solved per pixel in float32."""
    h, w, _ = color.shape
    t = nfor.TUNGSTEN
    weights = nl_means_window_weights(planes(guide), planes(guide_variance), 0, h, radius, patch, k, 1.0,
                                      t["nlm_epsilon"], nfor.DISTANCE_CLAMP, True, 1)
    eps = np.finfo(np.float32).eps
    acc = np.zeros((h, w, 3), np.float32)
    wacc = np.zeros((h, w), np.float32)
    feats = features.astype(np.float32)
    side = 2 * radius + 1
    for y in range(h):
        for x in range(w):
            iy, ix = np.mgrid[max(y - radius, 0):min(h, y + radius + 1), max(x - radius, 0):min(w, x + radius + 1)]
            iy, ix = iy.ravel(), ix.ravel()
            wt = weights[y, x, (iy - y + radius) * side + ix - x + radius].astype(np.float32)
            design = np.concatenate([np.ones((iy.size, 1), np.float32), (ix - x)[:, None].astype(np.float32),
                                     (iy - y)[:, None].astype(np.float32), feats[iy, ix] - feats[y, x]], axis=1)
            sw = np.sqrt(wt)
            a, b = sw[:, None] * design, sw[:, None] * color[iy, ix].astype(np.float32)
            q, r, perm = scipy.linalg.qr(a, pivoting=True, mode="economic")
            rank = int(np.sum(np.abs(np.diag(r)) > eps * np.linalg.norm(a, axis=0).max()))
            beta = np.zeros((design.shape[1], 3), np.float32)
            if rank:
                beta[perm[:rank]] = scipy.linalg.solve_triangular(r[:rank, :rank], q[:, :rank].T @ b)
            np.add.at(acc, (iy, ix), wt[:, None] * (design @ beta))
            np.add.at(wacc, (iy, ix), wt)
    return acc / wacc[..., None]


def errors(x, y) -> str:
    err = np.abs(np.asarray(x, np.float64) - y) / (np.abs(np.asarray(y, np.float64)) + 0.01)
    return f"max {err.max():.1e} median {np.median(err):.1e} p99 {np.quantile(err, 0.99):.1e}"


def main() -> None:
    from mcbench.analysis.metrics import relmse
    t = nfor.TUNGSTEN
    prefilter = nfor.prefilter_features
    for case in sorted(p for p in GOLDEN.iterdir() if (p / "scene.json").exists()):
        buffers = RenderBuffers(read_case(case), spp=int(case.name.rsplit("_spp", 1)[1]))

        def layer(name):
            return np.asarray(buffers.layers[name], dtype=np.float64)

        half_var = 2.0 * nfor._feature_variance(buffers)
        _, feat_b = prefilter(nfor._features(buffers, "_a"), nfor._features(buffers, "_b"), half_var,
                              epsilon=t["nlm_epsilon"], borders="truncate", clamp=nfor.DISTANCE_CLAMP)
        args = (layer("color_a"), layer("color_b"), 2.0 * layer("variance"), feat_b)
        f64 = nfor.collaborative_regression(*args, k=0.5, epsilon=t["nlm_epsilon"], feature_resolution=0.0,
                                            channels="min", borders="truncate", rank_threshold=t["rank_threshold"],
                                            pivot_tolerance=t["pivot_tolerance"])
        f32 = regression_float32(*args, k=0.5)
        rng = np.random.default_rng(0)

        def perturbed(*a, **kw):
            fa, fb = prefilter(*a, **kw)
            return tuple(f * (1.0 + ulps * 2.0 ** -24 * rng.uniform(-1.0, 1.0, f.shape)) for f in (fa, fb))

        clean = nfor.denoise(buffers, **t).full
        line = f"{case.name:22s} solve: {errors(f32, f64)}"
        for ulps in (1, 4):
            rng = np.random.default_rng(0)
            nfor.prefilter_features = perturbed
            try:
                noisy = nfor.denoise(buffers, **t).full
            finally:
                nfor.prefilter_features = prefilter
            line += f" | ulp {ulps}: {errors(noisy, clean)} relMSE {relmse(noisy, clean):.1e}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
