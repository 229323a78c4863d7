"""Two finished runs of the study side by side: what a change of the code did to the numbers.

    python tools/before_after.py BEFORE/results AFTER/results [--bases kpcn nfor_dc ...]

Prints Markdown: Table 3's Kendall tau against the paper (all eleven rows and the paper's six bases,
from ``tables/study/paper_table3.md``), each base's relMSE ranking score per spp and ``Avg.``
(``tables/ranking_relmse.csv``), each base's mean relMSE over the scenes per spp (``metrics.csv``),
the relMSE recommendations (``tables/study/recommendations.csv``: scope, key, ours and its share of
resamples) and each scene's reference floor ratio (``tables/scenes.csv``). Writes nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

BASES = ["kpcn", "nfor_dc", "mcgan", "nfor", "kpcn_dc", "oidn", "optix_ae", "rdfc"]


def _tau_lines(results: Path) -> list[str]:
    text = (results / "tables" / "study" / "paper_table3.md").read_text()
    return [line[2:] for line in text.splitlines() if line.startswith("- ") and "tau" in line]


def _mean_relmse(results: Path, names: list[str]) -> pd.DataFrame:
    metrics = pd.read_csv(results / "metrics.csv")
    if "entry" not in metrics.columns:  # a run of the code before the column was named entry
        metrics = metrics.rename(columns={"candidate": "entry"})
    rows = metrics[(metrics["metric"] == "relmse") & metrics["entry"].isin(names)]
    return rows.groupby(["entry", "spp"])["value"].mean().unstack("spp")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--bases", nargs="+", default=BASES)
    args = parser.parse_args(argv)
    before, after = args.before, args.after

    print("## Table 3 against the paper (Kendall tau)\n")
    for b, a in zip(_tau_lines(before), _tau_lines(after)):
        print(f"* before: {b}\n  after: {a}")

    print("\n## relMSE ranking score per spp (before → after)\n")
    rb = pd.read_csv(before / "tables" / "ranking_relmse.csv").set_index("candidate")
    ra = pd.read_csv(after / "tables" / "ranking_relmse.csv").set_index("candidate")
    columns = list(rb.columns)
    print("| base | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for name in args.bases + ["noisy"]:
        if name in rb.index and name in ra.index:
            print(f"| {name} | " + " | ".join(f"{rb.loc[name, c]:.1f} → {ra.loc[name, c]:.1f}" for c in columns) + " |")
    top_b = rb["Avg."].sort_values(ascending=False).head(5)
    top_a = ra["Avg."].sort_values(ascending=False).head(5)
    print("\nTop 5 by Avg.: before " + ", ".join(f"{n} {v:.1f}" for n, v in top_b.items())
          + "; after " + ", ".join(f"{n} {v:.1f}" for n, v in top_a.items()))

    print("\n## Mean relMSE over the scenes per spp (before → after)\n")
    mb, ma = _mean_relmse(before, args.bases + ["noisy"]), _mean_relmse(after, args.bases + ["noisy"])
    spps = list(mb.columns)
    print("| base | " + " | ".join(str(s) for s in spps) + " |")
    print("|---" * (len(spps) + 1) + "|")
    for name in mb.index:
        print(f"| {name} | " + " | ".join(f"{mb.loc[name, s]:.3g} → {ma.loc[name, s]:.3g}" for s in spps) + " |")

    print("\n## Recommendations, relMSE (before → after; share of resamples)\n")
    keep = ["scope", "key", "spp", "ours", "ours_fraction", "paper"]
    recb = pd.read_csv(before / "tables" / "study" / "recommendations.csv")
    reca = pd.read_csv(after / "tables" / "study" / "recommendations.csv")
    recb, reca = recb[recb["metric"] == "relmse"][keep], reca[reca["metric"] == "relmse"][keep]
    print("| scope | key | spp | before | after | paper |")
    print("|---|---|---|---|---|---|")
    for (_, b), (_, a) in zip(recb.iterrows(), reca.iterrows()):
        print(f"| {b['scope']} | {b['key']} | {b['spp']} | {b['ours']} ({b['ours_fraction']:.0%}) | "
              f"{a['ours']} ({a['ours_fraction']:.0%}) | {b['paper']} |")

    print("\n## Reference floor ratios (before → after)\n")
    sb = pd.read_csv(before / "tables" / "scenes.csv").set_index("scene")
    sa = pd.read_csv(after / "tables" / "scenes.csv").set_index("scene")
    print("| scene | reference spp | floor ratio |")
    print("|---|---|---|")
    for scene in sb.index:
        print(f"| {scene} | {sb.loc[scene, 'reference_spp']} → {sa.loc[scene, 'reference_spp']} | "
              f"{sb.loc[scene, 'floor_ratio']:.1f} → {sa.loc[scene, 'floor_ratio']:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
