"""How much does the image size move the ranking?

A slice of the study -- the candidates of the paper's Table 3 (bases #1 KPCN, #3 MCGAN, #4 NFOR,
#6 OIDN, #7 OptiX, #8 RDFC and ensembles #16, #24, #30, #33, #35) and the noisy input, on three
scenes of the default study at 4, 64 and 1024 spp -- is run by the workflow at 64², 128² and 256²
(the default config otherwise: 16384-spp references in 4 chunks), then scored by the paper's
score-and-rank (Sec. 5.3.3) on relMSE over the whole image and with an evaluation border of 21
pixels cut away (adobe/sbmc's evaluation crop). Reported: Kendall tau-b between the `Avg.`
orderings of every pair of settings, and of each setting against the paper's Table 3 (all 11
rows, and the six bases alone).

    python tools/resolution/study.py run  --work /tmp/resolution      # the three runs (their time: docs/resolution_study.md)
    python tools/resolution/study.py table --work /tmp/resolution     # the Markdown of docs/resolution_study.md

The three scenes are the ones of the default eight with the cheapest references
(envmap_objects, depth_of_field, fine_textures): the measurement needs references at 256²,
four times the default's pixels. Nothing is tuned on them; the result decides a default.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

SIZES = (64, 128, 256)
SCENES = ("envmap_objects", "depth_of_field", "fine_textures")
SPPS = (4, 64, 1024)
TABLE3_ENSEMBLES = (16, 24, 30, 33, 35)
CROP = 21          # pixels cut from each border (adobe/sbmc's evaluation)


def config_text(size: int) -> str:
    return (f"resolution: [{size}, {size}]\nscenes: [{', '.join(SCENES)}]\nspp: [{', '.join(map(str, SPPS))}]\n"
            f"denoisers: [oidn]\ncombiners: []\nstudy: {{ensembles: [{', '.join(map(str, TABLE3_ENSEMBLES))}]}}\n"
            f"metrics: [relmse, dssim]\n")


def run(work: Path) -> None:
    for size in SIZES:
        folder = work / f"res{size}"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "config.yaml").write_text(config_text(size))
        command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "--directory", str(folder),
                   "--configfile", str(folder / "config.yaml"), "--cores", "2", "results/metrics.csv"]
        print(" ".join(command), flush=True)
        subprocess.run(command, check=True)


def cropped_metrics(folder: Path, crop: int):
    """relMSE of every candidate and the noisy input with ``crop`` pixels cut from each border."""
    import pandas as pd

    from mcbench.analysis.metrics import relmse
    from mcbench.io.exr import read_layers

    full = pd.read_csv(folder / "results" / "metrics.csv")
    rows = []
    for (scene, spp), case in full[full["metric"] == "relmse"].groupby(["scene", "spp"]):
        reference = read_layers(folder / "results" / "references" / f"{scene}.exr", ["color"])["color"]
        window = (slice(crop, -crop), slice(crop, -crop))
        for entry in case["entry"]:
            path = (folder / "results" / "renders" / scene / f"spp{spp}.exr" if entry == "noisy" else
                    folder / "results" / "outputs" / scene / f"spp{spp}" / f"{entry}.exr")
            image = read_layers(path, ["color"])["color"]
            rows.append({"scene": scene, "spp": spp, "entry": entry, "metric": "relmse",
                         "value": relmse(image[window], reference[window])})
    return pd.DataFrame(rows)


def table(work: Path) -> str:
    import pandas as pd
    from scipy import stats

    from mcbench.analysis import pool
    from mcbench.analysis.ranking import ranking_table
    from mcbench.analysis.study.paper import PAPER_TABLE3_BASES, paper_kendall

    rankings = {}
    for size in SIZES:
        folder = work / f"res{size}"
        metrics = pd.read_csv(folder / "results" / "metrics.csv")
        rankings[(size, "whole")] = ranking_table(metrics, "relmse")
        rankings[(size, f"crop {CROP}")] = ranking_table(cropped_metrics(folder, CROP), "relmse")
    names = {cid: pool.candidate_name(cid) for cid in pool.PAPER_TABLE3}
    lines = ["| setting | τ vs paper, 11 rows (Avg.) | τ vs paper, 11 rows (common spp) | τ vs paper, 6 bases (common spp) | order (Avg., best first) |",
             "|---|---|---|---|---|"]
    for (size, crop), ranking in rankings.items():
        all_rows = paper_kendall(ranking, names=names).set_index("basis")
        base_rows = paper_kendall(ranking, names=names, ids=PAPER_TABLE3_BASES).set_index("basis")
        order = ", ".join(ranking.index)
        lines.append(f"| {size}², {crop} | {all_rows.loc['Avg.', 'tau']:.2f} | {all_rows.loc['Avg. (common spp)', 'tau']:.2f} | "
                     f"{base_rows.loc['Avg. (common spp)', 'tau']:.2f} | {order} |")
    lines += ["", "Kendall τ-b between the settings' `Avg.` orderings (12 entries):", "",
              "| | " + " | ".join(f"{s}², {c}" for s, c in rankings) + " |", "|---|" + "---|" * len(rankings)]
    for key_a in rankings:
        cells = []
        for key_b in rankings:
            a = rankings[key_a]["Avg."]
            b = rankings[key_b]["Avg."].loc[a.index]
            cells.append(f"{stats.kendalltau(a.values, b.values).statistic:.2f}")
        lines.append(f"| {key_a[0]}², {key_a[1]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("action", choices=["run", "table"])
    parser.add_argument("--work", type=Path, default=Path("/tmp/resolution"))
    args = parser.parse_args(argv)
    if args.action == "run":
        run(args.work)
    else:
        print(table(args.work))


if __name__ == "__main__":
    main()
