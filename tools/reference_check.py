"""How many ranks move when a scene's reference is replaced by another? (a one-off measurement)

    python tools/reference_check.py results --against veach_ajar=OTHER.exr fog_beams=OTHER2.exr \
        --spp 512 1024

``results`` is a finished run; each ``--against SCENE=PATH`` names another reference of that scene
(a merged reference EXR with ``color`` and ``variance`` layers, e.g. the 16384-spp reference of an
earlier run while ``results`` holds a 65536-spp one). The run's method outputs of those scenes at
``--spp`` are scored again, in this process, against the other reference (relMSE and the corrected
relMSE, :mod:`mcbench.analysis.metrics`, as the metrics jobs compute them), and for every metric
and spp it prints, between the run's own scores and the rescored ones, over the ranked pool of
``tables/ranking_relmse.csv`` (the 39 candidates and the noisy input):

* per scene: how many entries change their per-case score (rank), the largest change, Kendall's tau;
* for the ranking table's column at that spp (mean score over all scenes of the run): the same over
  the column's order, and the largest change of a column score;
* each reference's noise floor (:func:`mcbench.analysis.scene_summary.reference_relmse_floor`) and
  its ratio to the best pool candidate's relMSE at each spp.

Prints Markdown. Writes nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import kendalltau, rankdata

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mcbench.analysis.metrics import relmse, relmse_corrected  # noqa: E402
from mcbench.analysis.ranking import case_scores  # noqa: E402
from mcbench.analysis.scene_summary import reference_relmse_floor  # noqa: E402
from mcbench.io.buffers import Denoised, RenderBuffers  # noqa: E402
from mcbench.io.exr import read_layers  # noqa: E402

METRICS = {"relmse": lambda image, ref, var: relmse(image, ref),
           "relmse_corrected": lambda image, ref, var: relmse_corrected(image, ref, var)}


def _moves(old: pd.Series, new: pd.Series) -> tuple[int, float, float, float]:
    """Entries whose rank differs, the largest rank change, Kendall's tau, the largest score change."""
    old = old.sort_index()
    new = new.reindex(old.index)
    old_rank, new_rank = rankdata(-old.to_numpy()), rankdata(-new.to_numpy())
    return (int(np.sum(old_rank != new_rank)), float(np.max(np.abs(old_rank - new_rank))),
            float(kendalltau(old_rank, new_rank).statistic), float(np.max(np.abs(old.to_numpy() - new.to_numpy()))))


def rescored(results: Path, metrics: pd.DataFrame, pool: list[str], against: dict[str, Path],
             spps: list[int]) -> pd.DataFrame:
    """``metrics`` with the rows of ``against``'s scenes at ``spps`` scored against those references."""
    out = metrics.copy()
    for scene, path in against.items():
        layers = read_layers(str(path), ["color", "variance"])
        for spp in spps:
            images = {"noisy": RenderBuffers.load(results / "renders" / scene / f"spp{spp}.exr").color}
            for name in pool:
                if name != "noisy":
                    images[name] = Denoised.load(results / "outputs" / scene / f"spp{spp}" / f"{name}.exr").full
            for metric, function in METRICS.items():
                for name, image in images.items():
                    row = ((out["scene"] == scene) & (out["spp"] == spp) & (out["entry"] == name)
                           & (out["metric"] == metric))
                    if row.sum() != 1:
                        raise SystemExit(f"{results}/metrics.csv: no single row for {scene} {spp} {name} {metric}")
                    out.loc[row, "value"] = function(image, layers["color"], layers["variance"])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--against", nargs="+", required=True, metavar="SCENE=PATH")
    parser.add_argument("--spp", nargs="+", type=int, default=[512, 1024])
    args = parser.parse_args(argv)
    against = {item.split("=", 1)[0]: Path(item.split("=", 1)[1]) for item in args.against}
    pool = pd.read_csv(args.results / "tables" / "ranking_relmse.csv")["candidate"].astype(str).tolist()
    metrics = pd.read_csv(args.results / "metrics.csv")
    metrics = metrics[metrics["entry"].isin(pool) & metrics["metric"].isin(list(METRICS))]
    other = rescored(args.results, metrics, pool, against, args.spp)

    print("| scene | reference | floor (relMSE) | floor ratio per spp |")
    print("|---|---|---|---|")
    for scene, path in against.items():
        for label, ref_path, table in (("run's", args.results / "references" / f"{scene}.exr", metrics),
                                       ("other", path, other)):
            layers = read_layers(str(ref_path), ["color", "variance"])
            floor = reference_relmse_floor(layers["color"], layers["variance"])
            ratios = []
            for spp in args.spp:
                rows = table[(table["scene"] == scene) & (table["spp"] == spp) & (table["metric"] == "relmse")
                             & (table["entry"] != "noisy")]
                ratios.append(f"{spp}: {rows['value'].min() / floor:.1f}")
            print(f"| {scene} | {label} (`{ref_path}`) | {floor:.3g} | {', '.join(ratios)} |")
    print()
    print(f"| metric | spp | what | entries moved (of {len(pool)}) | largest move | Kendall tau | largest score change |")
    print("|---|---|---|---|---|---|---|")
    for metric in METRICS:
        own, changed = case_scores(metrics, metric), case_scores(other, metric)
        for spp in args.spp:
            for scene in against:
                pick = lambda s: s[(s["scene"] == scene) & (s["spp"] == spp)].set_index("entry")["score"]
                moved, largest, tau, score = _moves(pick(own), pick(changed))
                print(f"| {metric} | {spp} | {scene} (case) | {moved} | {largest:g} | {tau:.3f} | {score:g} |")
            column = lambda s: s[s["spp"] == spp].groupby("entry")["score"].mean()
            moved, largest, tau, score = _moves(column(own), column(changed))
            print(f"| {metric} | {spp} | table column | {moved} | {largest:g} | {tau:.3f} | {score:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
