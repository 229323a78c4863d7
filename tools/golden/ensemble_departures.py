"""Effect of each departure of our ensemble from the authors' program, on the golden cases.

    python tools/golden/ensemble_departures.py [--reference-spp 16384]

For every case of tests/data/golden/ensemble_cpp: our combine() as the program
(``AS_THE_PROGRAM`` of tests/combine/test_ensemble_golden.py), then with one departure at a time
(our default or reading), and our defaults as shipped. Prints a Markdown table: relMSE of each
against the program's ``blend.exr``, and relMSE against a reference of the case (rendered here:
the case's scene at 32 x 32 with ``--reference-spp`` samples, render seed 6, scaled like the golden
radiance), beside the program's own relMSE to that reference.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "combine"))

import methods.ensemble as E  # noqa: E402
from mcbench.pipeline.registry import load_scene  # noqa: E402
from mcbench.render.renderer import render_reference_chunk  # noqa: E402
from test_ensemble_golden import AS_THE_PROGRAM, CASES, DEPARTURES, load_case, relmse  # noqa: E402

sys.path.insert(0, str(ROOT / "tools" / "golden"))
from ensemble_cpp import EXPOSURE, RESOLUTION  # noqa: E402


def reference(scene: str, spp: int) -> np.ndarray:
    layers, _ = render_reference_chunk(load_scene(scene), spp, 0, resolution=RESOLUTION, seed=6, threads=1)
    return EXPOSURE * layers["color"].astype(np.float64)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reference-spp", type=int, default=16384)
    args = ap.parse_args(argv)
    references = {}
    rows = {"the program's blend.exr": {}, "ours as the program": {}}
    variants = {"ours as the program": {}, **{f"... but {k}": v for k, v in DEPARTURES.items()
                                              if not k.startswith("wrong constant")},
                "our defaults (shipped)": None}
    for case in CASES:
        scene = case.rsplit("_spp", 1)[0]
        if scene not in references:
            references[scene] = reference(scene, args.reference_spp)
        ref = references[scene]
        buffers, inputs, golden = load_case(case)
        rows["the program's blend.exr"][case] = (0.0, relmse(golden["blend"], ref))
        for label, change in variants.items():
            options = {"seed": 0} if change is None else {**AS_THE_PROGRAM, **change}
            full = E.combine(buffers, inputs, **options).full
            rows.setdefault(label, {})[case] = (relmse(full, golden["blend"]), relmse(full, ref))
    print("| variant | " + " | ".join(f"{c}: vs program / vs reference" for c in CASES) + " |")
    print("|---|" + "---|" * len(CASES))
    for label, values in rows.items():
        print(f"| {label} | " + " | ".join(f"{values[c][0]:.2e} / {values[c][1]:.4f}" for c in CASES) + " |")


if __name__ == "__main__":
    main()
