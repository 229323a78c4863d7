"""Where RDFC's error comes from on one render (docs/fidelity_rdfc.md, "glass_caustics at 4 spp").

    .venv/bin/python tools/rdfc/render_case.py glass_caustics --out /tmp/rdfc      # once
    NUMBA_NUM_THREADS=1 .venv/bin/python tools/rdfc/investigate.py glass_caustics --out /tmp/rdfc

Prints relMSE (against the reference of render_case.py) of the noisy input, RDFC as it is, its
pass-1 output, each pass-1 candidate alone, the per-pixel oracle over the candidates, the share
of pixels each selection picks, the share of the error in the worst pixels, and the variants
named by ``--variants`` (each a switch of methods/rdfc.py, see VARIANTS below).
"""

from __future__ import annotations

import time

import numpy as np

from mcbench.analysis.metrics import relmse, relmse_map
from mcbench.io.buffers import RenderBuffers
from methods import rdfc
from render_case import case_arguments  # tools/rdfc/, the script's own folder


def load(scene, spp, ref_spp, out):
    layers = dict(np.load(out / f"{scene}_spp{spp}.npz"))
    ref = np.load(out / f"{scene}_ref{ref_spp}.npz")["color"].astype(np.float64)
    return RenderBuffers(layers=layers, spp=spp), ref


def worst_share(err_map, frac):
    flat = np.sort(err_map.ravel())[::-1]
    k = max(1, int(round(frac * flat.size)))
    return flat[:k].sum() / flat.sum()


def trace(buffers, ref, **params):
    """RDFC's first pass of half buffer A step by step (as rdfc.denoise), with its intermediates."""
    y = np.asarray(buffers.layers["color_a"], dtype=np.float64)
    v = rdfc.half_variance(buffers, "a", params.get("variance", rdfc.VARIANCE))
    feats = rdfc.prefilter_features(buffers)
    filt, deriv, ovar = rdfc.candidate_filters(y, v, *feats["a"], radius=params.get("radius", rdfc.WINDOW_RADIUS),
                                               clamp_derivative=params.get("clamp_derivative", False))
    errors = rdfc.sure(filt, deriv, y, v).sum(axis=3)
    blend, _, sel = rdfc.select_and_blend(filt, ovar, errors, y, v)
    true_err = ((filt - ref) ** 2).sum(axis=3)
    return dict(y=y, v=v, filt=filt, deriv=deriv, errors=errors, blend=blend, sel=sel, true_err=true_err)


VARIANTS = {
    "default": {},
    "radius20": dict(radius=20),
    "clamp": dict(clamp_derivative=True),
    "noclamp": dict(clamp_derivative=False),
    "rescaled_var": dict(variance="rescaled"),
    "raw_var": dict(variance="raw"),
    "authors_pass2": dict(second_pass="authors"),
    "ours_pass2": dict(second_pass="ours"),
    "authors_pass2_clamp": dict(second_pass="authors", clamp_derivative=True),
    "ours_noclamp": dict(second_pass="ours", clamp_derivative=False, variance="raw", radius=10),
    "ours_noclamp_rescaled": dict(second_pass="ours", clamp_derivative=False, variance="rescaled", radius=10),
    "ours_noclamp_r20": dict(second_pass="ours", clamp_derivative=False, variance="raw", radius=20),
    "authors_all": dict(second_pass="authors", clamp_derivative=True, variance="rescaled"),
    "authors_all_r20": dict(second_pass="authors", clamp_derivative=True, variance="rescaled", radius=20),
}


def main(argv=None):
    ap = case_arguments(__doc__.splitlines()[0])
    ap.add_argument("--variants", default="default", help=f"comma-separated, of {sorted(VARIANTS)}")
    ap.add_argument("--trace", action="store_true", help="pass-1 details of half buffer A")
    args = ap.parse_args(argv)
    buffers, ref = load(args.scene, args.spp, args.ref_spp, args.out)
    noisy = np.asarray(buffers.layers["color"], dtype=np.float64)
    print(f"{args.scene} {args.spp} spp: noisy relMSE {relmse(noisy, ref):.4f} "
          f"(A {relmse(buffers.layers['color_a'], ref):.4f})")
    rdfc.denoise(RenderBuffers(layers={k: v[:32, :32] for k, v in buffers.layers.items()}, spp=buffers.spp))  # warm-up
    for name in args.variants.split(","):
        t = time.perf_counter()
        out = rdfc.denoise(buffers, **VARIANTS[name])
        dt = time.perf_counter() - t
        m = relmse_map(out.full, ref)
        print(f"  {name:14s} full {m.mean():.4f}  A {relmse(out.a, ref):.4f}  B {relmse(out.b, ref):.4f}  "
              f"worst 0.1% / 1% of pixels hold {worst_share(m, 1e-3):.0%} / {worst_share(m, 1e-2):.0%} "
              f"of the error  ({dt:.1f} s)")
    if args.trace:
        t = trace(buffers, ref)
        print("  pass 1 of A: relMSE of the blend %.4f; candidates %s; per-pixel oracle %.4f" % (
            relmse(t["blend"], ref),
            " ".join(f"{n} {relmse(f, ref):.4f}" for n, f in zip(rdfc.CANDIDATE_NAMES, t["filt"])),
            relmse(np.take_along_axis(t["filt"], t["true_err"].argmin(0)[None, ..., None], 0)[0], ref)))
        pick = np.argmin(t["errors"], axis=0)
        print("  SURE argmin (unfiltered maps) share FIRST/SECOND/THIRD: %s; oracle share: %s" % (
            " / ".join(f"{np.mean(pick == k):.2f}" for k in range(3)),
            " / ".join(f"{np.mean(t['true_err'].argmin(0) == k):.2f}" for k in range(3))))
        print("  mean selection weight FIRST/SECOND/THIRD: " + " / ".join(f"{t['sel'][..., k].mean():.2f}" for k in range(3)))
        d = t["deriv"]
        print("  share of pixel-channels with dF/dy outside [0, 1] per candidate: "
              + " / ".join(f"{np.mean((d[k] < 0) | (d[k] > 1)):.3f}" for k in range(3))
              + "; min dF/dy " + " / ".join(f"{d[k].min():.3g}" for k in range(3)))
        sure_mean = t["errors"].mean(axis=(1, 2))
        true_mean = (((t["filt"] - ref) ** 2).sum(axis=3) - ((t["y"] - ref) ** 2).sum(axis=2) * 0).mean(axis=(1, 2))
        print("  mean SURE vs true squared error per candidate: "
              + " / ".join(f"{s:.4g} vs {tr:.4g}" for s, tr in zip(sure_mean, true_mean)))
        ratio = t["v"] / np.maximum(((t["y"] - ref) ** 2), 1e-30)
        print(f"  colour variance of A vs its squared error: median ratio {np.median(ratio):.3f}")


if __name__ == "__main__":
    main()
