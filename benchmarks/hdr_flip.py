"""HDR-FLIP's cost per entry: NVIDIA's flip-evaluator against mcbench.analysis.hdr_flip, and how far apart.

    python benchmarks/hdr_flip.py RESULTS [--spp 64] [--entries 6] [--repeats 3]
    python benchmarks/hdr_flip.py RESULTS --table     # every entry against the run's own FLIP values

For each scene of a finished run (``RESULTS/references/<scene>.exr`` and the first ``--entries``
outputs of ``RESULTS/outputs/<scene>/spp<N>/``), alternating in each repeat and taking the best:

* ``package``: ``flip_evaluator.evaluate(reference, image, "HDR")``, one OpenMP thread (a case job
  has one), the former way of computing the metric;
* ``cold``: :func:`mcbench.analysis.metrics.flip_with_map` with no prepared reference kept (the
  first entry of a case: the reference's side is computed too);
* ``warm``: the same call with the reference's side kept (every other entry of the case).

Prints per scene the exposures, CPU milliseconds per entry of each, the ratios package / warm and
package / cold, and the largest differences of the maps and means from the package's; then the
machine's load averages. A case of E entries costs cold + (E - 1) warm.

With ``--table``: for a run whose ``metrics.csv`` holds FLIP values computed by flip-evaluator,
every entry whose image the run kept (``outputs/<scene>/spp<N>/<entry>.exr``, the noisy render)
is evaluated here again and compared: the largest relative difference of the means, and per case
the pairs of entries whose order by FLIP differs (with the package's gap between them).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.analysis import metrics  # noqa: E402
from mcbench.analysis.hdr_flip import exposure_levels  # noqa: E402
from mcbench.io.exr import read_layers  # noqa: E402


def _cpu_ms(call) -> tuple[float, object]:
    start = time.process_time()
    result = call()
    return 1e3 * (time.process_time() - start), result


def measure_scene(reference, images, *, repeats: int) -> dict:
    """Best-of-``repeats`` CPU ms per entry of the three ways (see the module), and the largest
    map and relative mean differences from the package."""
    import flip_evaluator

    reference = np.maximum(np.asarray(reference, np.float64), 0.0)
    best = {"package": np.inf, "cold": np.inf, "warm": np.inf}
    map_diff = mean_diff = 0.0
    for _ in range(repeats):
        package, cold, warm = [], [], []
        for image in images:
            image = np.maximum(np.asarray(image, np.float64), 0.0)
            ms, (pmap, pmean, _) = _cpu_ms(lambda: flip_evaluator.evaluate(
                np.float32(reference), np.float32(image), "HDR", applyMagma=False))
            package.append(ms)
            metrics._PREPARED_REFERENCES.clear()
            ms, _ = _cpu_ms(lambda: metrics.flip_with_map(image, reference))
            cold.append(ms)
            ms, (ours, mean) = _cpu_ms(lambda: metrics.flip_with_map(image, reference))
            warm.append(ms)
            map_diff = max(map_diff, float(np.abs(ours - np.asarray(pmap).reshape(ours.shape)).max()))
            mean_diff = max(mean_diff, abs(mean - pmean) / max(pmean, 1e-12))
        for name, values in (("package", package), ("cold", cold), ("warm", warm)):
            best[name] = min(best[name], float(np.mean(values)))
    return {**best, "map_diff": map_diff, "mean_diff": mean_diff}


def compare_with_table(results: Path) -> None:
    """The ``--table`` mode (see the module)."""
    import pandas as pd

    table = pd.read_csv(results / "metrics.csv")
    entry_column = "entry" if "entry" in table.columns else "candidate"
    flip_rows = table[table["metric"] == "flip"]
    worst, swaps, pairs, evaluations = 0.0, [], 0, 0
    for (scene, spp), case in flip_rows.groupby(["scene", "spp"]):
        reference = read_layers(results / "references" / f"{scene}.exr", ["color"])["color"]
        package, ours = {}, {}
        for entry, value in zip(case[entry_column], case["value"]):
            path = (results / "renders" / scene / f"spp{spp}.exr" if entry == "noisy"
                    else results / "outputs" / scene / f"spp{spp}" / f"{entry}.exr")
            if not path.exists():
                continue
            ours[entry] = metrics.flip(read_layers(path, ["color"])["color"], reference)
            package[entry] = float(value)
            worst = max(worst, abs(ours[entry] - package[entry]) / max(package[entry], 1e-12))
        evaluations += len(ours)
        names = sorted(ours)
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                pairs += 1
                if (package[a] - package[b]) * (ours[a] - ours[b]) < 0 or \
                        ((package[a] == package[b]) != (ours[a] == ours[b])):
                    swaps.append((scene, spp, a, b, abs(package[a] - package[b])))
    print(f"{evaluations} entries of {flip_rows.groupby(['scene', 'spp']).ngroups} cases; largest relative "
          f"difference of the means {worst:.2e}; {len(swaps)} of {pairs} pairs ordered differently")
    for scene, spp, a, b, gap in swaps:
        print(f"  {scene} spp{spp}: {a} / {b}, the package's gap {gap:.2e}")
    print("load " + " ".join(f"{x:.2f}" for x in os.getloadavg()))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--entries", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--table", action="store_true")
    args = parser.parse_args(argv)
    if args.table:
        compare_with_table(args.results)
        return
    print(f"{'scene':16s} {'exp':>3s} {'package':>8s} {'cold':>7s} {'warm':>7s} {'pkg/warm':>8s} {'pkg/cold':>8s} "
          f"{'max |dmap|':>10s} {'mean rel':>9s}   (CPU ms per entry)")
    totals = {"package": 0.0, "warm": 0.0}
    for path in sorted((args.results / "references").glob("*.exr")):
        scene = path.stem
        outputs = sorted((args.results / "outputs" / scene / f"spp{args.spp}").glob("*.exr"))[:args.entries]
        if not outputs:
            continue
        reference = read_layers(path, ["color"])["color"]
        images = [read_layers(output, ["color"])["color"] for output in outputs]
        start, stop = metrics.flip_exposure_range(np.maximum(reference, 0.0))
        exposures = len(exposure_levels(start, stop))
        row = measure_scene(reference, images, repeats=args.repeats)
        totals["package"] += row["package"]
        totals["warm"] += row["warm"]
        print(f"{scene:16s} {exposures:3d} {row['package']:8.1f} {row['cold']:7.1f} {row['warm']:7.1f} "
              f"{row['package'] / row['warm']:8.1f} {row['package'] / row['cold']:8.1f} "
              f"{row['map_diff']:10.2e} {row['mean_diff']:9.1e}")
    if totals["warm"]:
        print(f"all scenes: package / warm {totals['package'] / totals['warm']:.1f}")
    print("load " + " ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
