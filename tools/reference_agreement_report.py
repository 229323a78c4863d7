"""The reference check on real renders: false alarms and power, from a finished run (a measurement).

    python tools/reference_agreement_report.py results [--patches 40]

For every scene of the finished run ``results``, its merged reference (``references/<scene>.exr``)
is tested (:func:`mcbench.analysis.reference_check.reference_agreement`, as the rule
``check_reference`` calls it) against each of the run's independent noisy renders of the scene
(every spp, the full image and its two halves: 27 renders per scene in the default study). Each
is a correct reference against its own renderer, so every refusal is a false alarm. Printed per
scene: the renders tested, the refusals, the largest local and global statistics and their
thresholds. Then the power at the highest spp (full image): the relative bias of one channel over
a block-aligned 16 x 16 region that reaches the local threshold (median and 90th percentile over
the blocks and channels), how many of ``--patches`` references biased by 2 % in one random
channel over a random 16 x 16 region are refused, and whether a reference 0.5 %, 1 % and 2 %
brighter everywhere is refused.

Prints Markdown. Writes nothing. Random patches from a fixed seed (0).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mcbench.analysis.reference_check import reference_agreement  # noqa: E402
from mcbench.io.exr import read_layers, read_metadata  # noqa: E402


def _renders(results: Path, scene: str):
    """(spp label, color, variance, spp) of every noisy render of the scene: full image and halves."""
    for path in sorted((results / "renders" / scene).glob("spp*.exr"), key=lambda p: int(p.stem[3:])):
        spp = int(read_metadata(str(path))["spp"])
        layers = read_layers(str(path), ["color", "variance", "color_a", "variance_a", "color_b", "variance_b"])
        yield f"{spp}", layers["color"], layers["variance"], spp
        for half in ("a", "b"):
            yield f"{spp}{half}", layers[f"color_{half}"], layers[f"variance_{half}"], spp // 2


def _detectable_bias(reference, reference_variance, render_variance, *, reference_spp, render_spp, threshold,
                     block=16) -> np.ndarray:
    """Per aligned block and channel: the relative bias of the reference's mean that makes |z| reach
    ``threshold`` (the block's standard deviation of the difference over its mean, times it)."""
    h, w = (reference.shape[0] // block) * block, (reference.shape[1] // block) * block
    variance = np.maximum(render_variance, reference_variance * reference_spp / render_spp) + reference_variance
    blocks = lambda image: image[:h, :w].reshape(h // block, block, w // block, block, 3).sum(axis=(1, 3))
    sd = np.sqrt(blocks(variance.astype(np.float64))) / (block * block)
    mean = blocks(np.abs(reference.astype(np.float64))) / (block * block)
    return threshold * sd / np.maximum(mean, 1e-12)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--patches", type=int, default=40)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    scenes = sorted(p.stem for p in (args.results / "references").glob("*.exr"))
    false_alarms, power = [], []
    for scene in scenes:
        path = args.results / "references" / f"{scene}.exr"
        reference_spp = int(read_metadata(str(path))["spp"])
        layers = read_layers(str(path), ["color", "variance"])
        ref, ref_var = layers["color"], layers["variance"]
        results = []
        for label, color, variance, spp in _renders(args.results, scene):
            agreement = reference_agreement(ref, ref_var, color, variance, reference_spp=reference_spp, render_spp=spp)
            results.append((label, agreement))
        refused = [label for label, a in results if not a.passed]
        worst_local = max(results, key=lambda r: r[1].max_z)
        worst_global = max(results, key=lambda r: r[1].global_statistic)
        false_alarms.append(
            f"| {scene} | {reference_spp} | {len(results)} | {len(refused)} {' '.join(refused)} | "
            f"{worst_local[1].max_z:.2f} ({worst_local[0]}) / {worst_local[1].local_threshold:.2f} | "
            f"{worst_global[1].global_statistic:.2f} ({worst_global[0]}) / {worst_global[1].global_threshold:.2f} |")
        label, full = max(((l, a) for l, a in results if l.isdigit()), key=lambda r: int(r[0]))
        top = next(r for r in _renders(args.results, scene) if r[0] == label)
        _, color, variance, spp = top
        bias = _detectable_bias(ref, ref_var, variance, reference_spp=reference_spp, render_spp=spp,
                                threshold=full.local_threshold)
        refused_patches = 0
        for _ in range(args.patches):
            row, column = (int(rng.integers(0, s - 16 + 1)) for s in ref.shape[:2])
            channel = int(rng.integers(0, 3))
            biased = ref.copy()
            biased[row:row + 16, column:column + 16, channel] *= 1.02
            refused_patches += not reference_agreement(biased, ref_var, color, variance, reference_spp=reference_spp,
                                                       render_spp=spp).passed
        brighter = ["refused" if not reference_agreement(ref * f, ref_var * f * f, color, variance,
                                                         reference_spp=reference_spp, render_spp=spp).passed
                    else "passes" for f in (1.005, 1.01, 1.02)]
        power.append(f"| {scene} | {spp} | {np.median(bias) * 100:.2f} % | {np.percentile(bias, 90) * 100:.2f} % | "
                     f"{refused_patches} of {args.patches} | {' / '.join(brighter)} |")
    print("| scene | reference spp | renders tested | refused | largest local (render) / threshold "
          "| largest global (render) / threshold |")
    print("|---|---:|---:|---|---|---|")
    print("\n".join(false_alarms))
    print()
    print("| scene | render spp | bias detected in a block: median | 90th percentile | 2 % patches refused "
          "| brighter by 0.5 / 1 / 2 % |")
    print("|---|---:|---:|---:|---|---|")
    print("\n".join(power))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
