"""Measure each departure of our NFOR from Tungsten's on the stored golden cases.

For every case in ``tests/data/golden/tungsten_nfor/`` (made by ``tools/golden/tungsten_nfor.py``)
our NFOR runs with every switch at Tungsten's behaviour (its defaults, ``methods.nfor.TUNGSTEN``),
then with each switch at its paper-reading setting (``methods.nfor.PAPER_READING``) in turn, then with all of
``PAPER_READING``. Per variant it
reports the relMSE (:func:`mcbench.analysis.metrics.relmse`) of our output against Tungsten's
output (the golden) and against the scene's reference render, averaged over the cases, per spp
level. Prints a Markdown table (``--out`` also writes it)::

    . .venv/bin/activate
    python tools/golden/tungsten_nfor_departures.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from mcbench.analysis.metrics import relmse  # noqa: E402
from mcbench.io.buffers import RenderBuffers  # noqa: E402
from mcbench.io.tungsten_buffers import read_case, read_pfm  # noqa: E402
from methods import nfor  # noqa: E402

GOLDEN = ROOT / "tests" / "data" / "golden" / "tungsten_nfor"
OUTPUT_FILE = "tungsten_nfor.pfm"

#: switch -> what setting it to its former value (``nfor.PAPER_READING``) does (the row label).
SWITCHES = {
    "regression_channels": "regression weights from the channel-mean distance (not min over channels)",
    "filter_channels": "MSE/selection filter weights from the channel-mean distance (not per channel)",
    "nlm_epsilon": "NL-means epsilon 1e-10 (not 1e-7)",
    "feature_variance": "prefilter variance (f_A - f_B)^2 / 2 (not 2 x feature variance of the mean)",
    "color_variance": "pass-1 guide/MSE variance variance_b, variance_a (not 2 x variance of the mean)",
    "second_pass_variance_scale": "second-pass variance (r_A - r_B)^2 / 4 (not / 2)",
    "patch_borders": "edge-replicated patches (not truncated means)",
    "filter_clamp": "no distance clamp in NL-means filters",
    "feature_resolution": "feature differences below 1e-9 relative count as 0",
    "rank_threshold": "no Eigen-like rank rule (column norm <= eps_32 x largest)",
    "pivot_tolerance": "scaled Cholesky pivot tolerance 1e-9 (not eps_32^2)",
}


def load_cases(folder: Path) -> list[dict]:
    """Every case folder with an output: name, spp, buffers, golden output, reference (or None)."""
    cases = []
    for case in sorted(p for p in folder.iterdir() if (p / OUTPUT_FILE).exists()):
        scene, spp = case.name.rsplit("_spp", 1)
        ref = folder / f"{scene}_reference.pfm"
        cases.append({"name": case.name, "scene": scene, "spp": int(spp),
                      "buffers": RenderBuffers(read_case(case), spp=int(spp), source=str(case)),
                      "golden": read_pfm(case / OUTPUT_FILE).astype(np.float64),
                      "reference": read_pfm(ref).astype(np.float64) if ref.exists() else None})
    return cases


def variants() -> list[tuple[str, dict]]:
    """(label, switches) for Tungsten (the defaults), each switch at its former value, and all of PAPER_READING."""
    former = nfor.PAPER_READING
    rows = [("all switches at Tungsten's behaviour (the defaults)", dict(nfor.TUNGSTEN))]
    for switch, label in SWITCHES.items():
        rows.append((f"`{switch}={former[switch]!r}`: {label}", dict(nfor.TUNGSTEN, **{switch: former[switch]})))
    rows.append(("all switches at their former values (`nfor.PAPER_READING`, the former NFOR)", dict(former)))
    return rows


def measure(cases: list[dict]) -> list[dict]:
    spps = sorted({c["spp"] for c in cases})
    results = []
    for label, switches in variants():
        row = {"variant": label}
        for spp in spps:
            subset = [c for c in cases if c["spp"] == spp]
            outs = [np.asarray(nfor.denoise(c["buffers"], **switches).full, dtype=np.float64) for c in subset]
            row[f"golden_{spp}"] = float(np.mean([relmse(o, c["golden"]) for o, c in zip(outs, subset)]))
            refs = [(o, c) for o, c in zip(outs, subset) if c["reference"] is not None]
            row[f"ref_{spp}"] = float(np.mean([relmse(o, c["reference"]) for o, c in refs])) if refs else float("nan")
        results.append(row)
        print(f"done: {label}", file=sys.stderr, flush=True)
    tungsten = {"variant": "Tungsten's output itself"}
    for spp in spps:
        subset = [c for c in cases if c["spp"] == spp and c["reference"] is not None]
        tungsten[f"golden_{spp}"] = 0.0
        tungsten[f"ref_{spp}"] = float(np.mean([relmse(c["golden"], c["reference"]) for c in subset]))
    results.append(tungsten)
    return results


def table(results: list[dict], cases: list[dict]) -> str:
    spps = sorted({c["spp"] for c in cases})
    scenes = sorted({c["scene"] for c in cases})
    head = ["variant"] + [f"vs Tungsten, {s} spp" for s in spps] + [f"vs reference, {s} spp" for s in spps]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in results:
        cells = [row["variant"]] + [f"{row[f'golden_{s}']:.3g}" for s in spps] + [f"{row[f'ref_{s}']:.4g}" for s in spps]
        lines.append("| " + " | ".join(cells) + " |")
    return (f"relMSE, mean over the scenes {', '.join(scenes)} "
            f"({cases[0]['golden'].shape[1]}x{cases[0]['golden'].shape[0]} px)\n\n" + "\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--golden", type=Path, default=GOLDEN)
    parser.add_argument("--out", type=Path, help="also write the Markdown table here")
    args = parser.parse_args(argv)
    cases = load_cases(args.golden)
    if not cases:
        raise SystemExit(f"no golden cases in {args.golden}")
    text = table(measure(cases), cases)
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
