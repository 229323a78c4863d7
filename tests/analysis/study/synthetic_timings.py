"""A tiny timed study for the figures' tests: metrics whose noisy relmse is an exact power law,
methods timed at known seconds, render times proportional to spp, render records on disk."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from mcbench.io.exr import write_layers

SCENES = ["box", "glass_room"]
SPPS = [4, 8, 16, 32]
# pool names: bases #1 KPCN, #4 NFOR, #8 RDFC, #5 KPCN-DC (takes kpcn); ensembles #10 {1,4}, #18 {1,4,8}
METHODS = ["kpcn", "nfor", "rdfc", "kpcn_dc", "ens10", "ens18"]
INPUTS = {"kpcn_dc": ["kpcn"], "ens10": ["kpcn", "nfor"], "ens18": ["kpcn", "nfor", "rdfc"]}
OWN = {"kpcn": 2.0, "nfor": 3.0, "rdfc": 0.5, "kpcn_dc": 1.0, "ens10": 0.25, "ens18": 0.125}
RENDER_SECONDS_PER_SPP = 0.05
NOISY_CONSTANT = 0.8  # noisy relmse = NOISY_CONSTANT / spp


def synthetic_study(seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Metrics (relmse, dssim) and timings of a tiny study: the noisy relmse is an exact power
    law, the methods' errors random below it; each method's seconds are its OWN value in every
    case (timed twice, once 10 % faster and once 10 % slower)."""
    rng = np.random.default_rng(seed)
    rows = []
    for scene, spp in itertools.product(SCENES, SPPS):
        for metric in ("relmse", "dssim"):
            rows.append({"scene": scene, "spp": spp, "entry": "noisy", "metric": metric,
                         "value": NOISY_CONSTANT / spp})
            for name in METHODS:
                rows.append({"scene": scene, "spp": spp, "entry": name, "metric": metric,
                             "value": float(rng.uniform(0.05, 0.9)) * NOISY_CONSTANT / spp})
    metrics = pd.DataFrame(rows).sample(frac=1.0, random_state=seed)  # row order must not matter
    timings = pd.DataFrame([{"scene": scene, "spp": spp, "method": name, "seconds": OWN[name] * factor}
                            for scene, spp, name, factor in itertools.product(SCENES, SPPS, METHODS, (0.9, 1.1))])
    return metrics, timings


def render_times(scale: float = RENDER_SECONDS_PER_SPP) -> pd.DataFrame:
    return pd.DataFrame([{"scene": scene, "spp": spp, "seconds": scale * spp, "source": "exr"}
                         for scene, spp in itertools.product(SCENES, SPPS)])


def write_records(tmp_path) -> list[str]:
    """Render records of the synthetic study: benchmark TSVs for every case and, for box at 4
    spp, an EXR whose header time differs (the EXR's must win)."""
    paths = []
    for scene, spp in itertools.product(SCENES, SPPS):
        path = tmp_path / "benchmarks" / "render_noisy" / f"{scene}_spp{spp}.tsv"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("s\th:m:s\tmax_rss\tcpu_time\n"
                        f"{RENDER_SECONDS_PER_SPP * spp:.6f}\t0:00:00\t10.0\t{RENDER_SECONDS_PER_SPP * spp:.6f}\n")
        paths.append(str(path))
    exr = tmp_path / "renders" / "box" / "spp4.exr"
    exr.parent.mkdir(parents=True, exist_ok=True)
    write_layers(exr, {"color": np.ones((2, 2, 3), np.float32)}, metadata={"scene": "box", "spp": 4, "seconds": 0.1})
    return paths + [str(exr)]
