"""How many ranks move when a scene's reference is replaced by a cleaner one? (a one-off measurement)

    python tools/reference_check.py RESULTS_OLD RESULTS_NEW --scenes veach_ajar fog_beams --spp 512 1024

``RESULTS_OLD`` and ``RESULTS_NEW`` are two finished runs of the same study whose method outputs are
the same and whose references differ only for ``--scenes`` (e.g. 16384 against 65536 spp: run the
study, copy its ``results/`` and rerun with a config that raises ``reference.scene_spp`` for those
scenes; Snakemake then re-renders only their references and rescores their cases). For every metric
in ``--metrics`` and every ``--spp`` it prints, from each run's ``metrics.csv`` and the pool of
``tables/ranking_relmse.csv`` (the 39 candidates and the noisy input):

* per changed scene: how many of the entries change their per-case score (rank), the largest change,
  and Kendall's tau between the two orderings;
* for the ranking table's column at that spp (mean score over all scenes): how many entries change
  their position in the column's order, the largest change, Kendall's tau, and the largest change of
  a column score;
* the old and new reference's noise floor ratio of each changed scene (best candidate's relMSE at the
  highest spp over the reference's own estimated relMSE, ``tables/scenes.csv``).

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

from mcbench.analysis.ranking import case_scores  # noqa: E402


def _pool(results: Path) -> list[str]:
    return pd.read_csv(results / "tables" / "ranking_relmse.csv")["candidate"].astype(str).tolist()


def _scores(results: Path, metric: str, pool: list[str]) -> pd.DataFrame:
    metrics = pd.read_csv(results / "metrics.csv")
    metrics = metrics[metrics["candidate"].isin(pool) & (metrics["metric"] == metric)]
    return case_scores(metrics, metric)


def _moves(old: pd.Series, new: pd.Series) -> tuple[int, float, float]:
    """Entries whose rank differs, the largest rank change, Kendall's tau of the two orders."""
    old, new = old.sort_index(), new.reindex(old.sort_index().index)
    old_rank, new_rank = rankdata(-old.to_numpy()), rankdata(-new.to_numpy())
    changed = int(np.sum(old_rank != new_rank))
    largest = float(np.max(np.abs(old_rank - new_rank))) if len(old_rank) else 0.0
    tau = float(kendalltau(old_rank, new_rank).statistic)
    return changed, largest, tau


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--scenes", nargs="+", required=True)
    parser.add_argument("--spp", nargs="+", type=int, default=[512, 1024])
    parser.add_argument("--metrics", nargs="+", default=["relmse", "relmse_corrected"])
    args = parser.parse_args(argv)
    pool = _pool(args.old)
    if sorted(pool) != sorted(_pool(args.new)):
        raise SystemExit("the two runs rank different pools")
    for path in (args.old, args.new):
        scenes = pd.read_csv(path / "tables" / "scenes.csv").set_index("scene")
        print(f"* `{path}`: " + "; ".join(
            f"{s} reference {scenes.loc[s, 'reference_spp']} spp, floor ratio {scenes.loc[s, 'floor_ratio']:.2f}"
            for s in args.scenes))
    print()
    print("| metric | spp | what | entries moved (of %d) | largest move | Kendall tau | largest score change |" % len(pool))
    print("|---|---|---|---|---|---|---|")
    for metric in args.metrics:
        old, new = _scores(args.old, metric, pool), _scores(args.new, metric, pool)
        for spp in args.spp:
            for scene in args.scenes:
                pick = lambda s: s[(s["scene"] == scene) & (s["spp"] == spp)].set_index("candidate")["score"]
                a, b = pick(old), pick(new)
                changed, largest, tau = _moves(a, b)
                print(f"| {metric} | {spp} | {scene} (case) | {changed} | {largest:g} | {tau:.3f} | "
                      f"{float(np.max(np.abs(a.sort_index() - b.reindex(a.sort_index().index)))):g} |")
            column = lambda s: s[s["spp"] == spp].groupby("candidate")["score"].mean()
            a, b = column(old), column(new)
            changed, largest, tau = _moves(a, b)
            print(f"| {metric} | {spp} | table column | {changed} | {largest:g} | {tau:.3f} | "
                  f"{float(np.max(np.abs(a.sort_index() - b.reindex(a.sort_index().index)))):.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
