"""The weight filter's details (the public code's passes and readings of Eq. 33), measured on a
finished study: each switch of ``methods.ensemble.combine`` (``guide_variance_blur``,
``outlier_removal``, ``colour_distance``, ``filter_border``, ``normal_features``) against the
default, on every case of the run, for three input sets. The defaults are decided by the paper's
text and the authors' code, not by these numbers (they describe what each choice does); run it
on validation renders, not to pick a default on the test scenes.

    python benchmarks/bench_postprocess.py [--results /tmp/run/results] [--scenes a b] [--spp 4 8]

Reads ``renders/{scene}/spp{N}.exr`` (RenderBuffers), the base outputs
``outputs/{scene}/spp{N}/{method}.exr`` (Denoised) and ``references/{scene}.exr``; runs the
ensemble (iterative solver, the paper's filter parameters) per variant and prints, per input set
and variant, the mean over the cases of relMSE and DSSIM (``mcbench.analysis.metrics``), the change of mean
relMSE against the default in percent, and the fraction of cases the variant improves.
As a check of the harness it also prints the largest relMSE between our default and the run's
own ``ens_*`` output where the run has one (it was written by the code of that run).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.io.buffers import Denoised, RenderBuffers  # noqa: E402
from mcbench.io.exr import read_layers  # noqa: E402
from mcbench.analysis.metrics import dssim, relmse  # noqa: E402
from methods import ensemble  # noqa: E402

INPUT_SETS = {"ens_oidn_nfor_rdfc": ["oidn", "nfor", "rdfc"],
              "ens_kpcn_nfor_oidn_rdfc": ["kpcn", "nfor", "oidn", "rdfc"],
              "ens_all": ["oidn", "jbf", "nfor", "rdfc"]}
PAPER = dict(guide_variance_blur="none", outlier_removal="none", filter_border="clip", variance_sum_floor=0.0)
VARIANTS = {
    "default": {},
    "paper filter": PAPER,
    "paper + blur": dict(PAPER, guide_variance_blur="gaussian9"),
    "paper + code outliers": dict(PAPER, outlier_removal="public_code"),
    "paper + mean outliers": dict(PAPER, outlier_removal="neighbour_mean"),
    "mean colour distance": dict(colour_distance="mean"),
    "clipped borders": dict(filter_border="clip"),
    "standardised normal": dict(normal_features="standardised"),
}


def cases(results: Path, scenes=None, spps=None):
    """(scene, spp) of every render that has base outputs, sorted."""
    found = []
    for render in sorted(results.glob("renders/*/spp*.exr")):
        scene, spp = render.parent.name, int(render.stem[3:])
        if (scenes and scene not in scenes) or (spps and spp not in spps):
            continue
        if (results / "outputs" / scene / f"spp{spp}").is_dir():
            found.append((scene, spp))
    return found


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=Path("/tmp/run/results"))
    ap.add_argument("--scenes", nargs="*")
    ap.add_argument("--spp", nargs="*", type=int)
    args = ap.parse_args(argv)
    todo = cases(args.results, args.scenes, args.spp)
    if not todo:
        raise SystemExit(f"no cases under {args.results}")
    errors = {(s, v): [] for s in INPUT_SETS for v in VARIANTS}   # lists of (relmse, dssim)
    harness_check = 0.0
    start = time.perf_counter()
    for scene, spp in todo:
        case = args.results / "outputs" / scene / f"spp{spp}"
        buffers = RenderBuffers.load(args.results / "renders" / scene / f"spp{spp}.exr")
        reference = read_layers(args.results / "references" / f"{scene}.exr", ["color"])["color"]
        outputs = {}
        for set_name, methods in INPUT_SETS.items():
            inputs = [outputs.setdefault(m, Denoised.load(case / f"{m}.exr")) for m in methods]
            for variant, params in VARIANTS.items():
                image = ensemble.combine(buffers, inputs, **params).full
                errors[set_name, variant].append((relmse(image, reference), dssim(image, reference)))
                if variant == "default" and (case / f"{set_name}.exr").exists():
                    stored = Denoised.load(case / f"{set_name}.exr").full
                    harness_check = max(harness_check, relmse(image, stored))
        print(f"  {scene} spp{spp} done ({time.perf_counter() - start:.0f} s)", file=sys.stderr,
              flush=True)
    print(f"{len(todo)} cases from {args.results}; largest relMSE of our default against the "
          f"run's own ens_* output: {harness_check:.1e}")
    print(f"{'input set':<24} {'variant':<18} {'relMSE':>9} {'DSSIM':>8} {'d relMSE':>9} "
          f"{'d DSSIM':>8} {'better':>7}")
    overall = {v: [] for v in VARIANTS}
    for set_name in INPUT_SETS:
        base = np.array(errors[set_name, "default"])
        for variant in VARIANTS:
            e = np.array(errors[set_name, variant])
            overall[variant].append(e)
            print(f"{set_name:<24} {variant:<18} {e[:, 0].mean():9.5f} {e[:, 1].mean():8.5f} "
                  f"{100 * (e[:, 0].mean() / base[:, 0].mean() - 1):+8.2f}% "
                  f"{100 * (e[:, 1].mean() / base[:, 1].mean() - 1):+7.2f}% "
                  f"{(e[:, 0] < base[:, 0]).mean():7.2f}")
    base = np.concatenate(overall["default"])
    print("all three sets together:")
    for variant in VARIANTS:
        e = np.concatenate(overall[variant])
        print(f"{'':<24} {variant:<18} {e[:, 0].mean():9.5f} {e[:, 1].mean():8.5f} "
              f"{100 * (e[:, 0].mean() / base[:, 0].mean() - 1):+8.2f}% "
              f"{100 * (e[:, 1].mean() / base[:, 1].mean() - 1):+7.2f}% "
              f"{(e[:, 0] < base[:, 0]).mean():7.2f}")


if __name__ == "__main__":
    main()
