"""Two runs of one config under the two feature conventions side by side (docs/fidelity_features.md).

    python tools/features_before_after.py FIRST_HIT/results TUNGSTEN/results [--metric relmse]

Prints Markdown: each entry's mean error per spp in both runs and their ratio (tungsten / first-hit),
over all scenes, over the scenes with a delta lobe (a smooth mirror, glass or coated surface, where the
conventions differ most) and over the others, then the per-scene table of the entries at each spp. The
scenes with a delta lobe are found by loading each scene with Mitsuba and reading its BSDFs' flags
(``DeltaReflection`` or ``DeltaTransmission``). An emitter's albedo (its radiance added) differs too,
in every scene whose camera sees a light. The noisy input (`noisy`) is the control: its colour is the same in both runs
(the conventions change the features only), so its ratio must be 1. Writes nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def scenes_with_delta_lobes(scenes: list[str]) -> set[str]:
    """The scenes (names of ``scenes/``) with a BSDF that has a delta reflection or transmission lobe
    (not Mitsuba's ``null`` interface of a medium, which both conventions cross), at 16x16 pixels."""
    import mitsuba as mi

    from mcbench.render.variants import pick_variant
    from scenes import load_scene, scene_spec

    pick_variant("auto")
    found = set()
    for name in scenes:
        scene = mi.load_dict(scene_spec(load_scene(name)).build(16, 16))
        flags = [shape.bsdf().flags() for shape in scene.shapes() if shape.bsdf() is not None]
        delta = int(mi.BSDFFlags.DeltaReflection) | int(mi.BSDFFlags.DeltaTransmission)
        if any(int(flag) & delta for flag in flags):
            found.add(name)
    return found


def mean_errors(metrics: pd.DataFrame, metric: str, scenes) -> pd.DataFrame:
    """Mean of ``metric`` over ``scenes`` per entry (rows) and spp (columns)."""
    rows = metrics[(metrics["metric"] == metric) & metrics["scene"].isin(scenes)]
    return rows.groupby(["entry", "spp"])["value"].mean().unstack("spp")


def side_by_side(first: pd.DataFrame, tungsten: pd.DataFrame) -> pd.DataFrame:
    """``first / tungsten / ratio`` columns per spp."""
    columns = {}
    for spp in first.columns:
        columns[(spp, "first_hit")] = first[spp]
        columns[(spp, "tungsten")] = tungsten[spp]
        columns[(spp, "ratio")] = tungsten[spp] / first[spp].where(first[spp] > 0)
    table = pd.DataFrame(columns)
    table.columns = [f"{spp} {kind}" for spp, kind in table.columns]
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("first_hit", type=Path, help="results/ of the first-hit run")
    parser.add_argument("tungsten", type=Path, help="results/ of the tungsten run")
    parser.add_argument("--metric", default="relmse")
    args = parser.parse_args()
    first, tungsten = (pd.read_csv(folder / "metrics.csv") for folder in (args.first_hit, args.tungsten))
    scenes = sorted(set(first["scene"]))
    if sorted(set(tungsten["scene"])) != scenes:
        raise SystemExit("the two runs have different scenes")
    delta = scenes_with_delta_lobes(scenes)
    groups = {"all scenes": scenes, "scenes with a delta lobe: " + ", ".join(sorted(delta)): sorted(delta),
              "the other scenes": [s for s in scenes if s not in delta]}
    for title, members in groups.items():
        if not members:
            continue
        print(f"### mean {args.metric}, {title}\n")
        print(side_by_side(mean_errors(first, args.metric, members),
                           mean_errors(tungsten, args.metric, members)).to_markdown(floatfmt=".4g"))
        print()
    print(f"### {args.metric} per scene (tungsten / first-hit)\n")
    keys = ["scene", "spp", "entry"]
    merged = first[first["metric"] == args.metric].merge(tungsten[tungsten["metric"] == args.metric], on=keys,
                                                         suffixes=("_first_hit", "_tungsten"))
    merged["ratio"] = merged["value_tungsten"] / merged["value_first_hit"].where(merged["value_first_hit"] > 0)
    print(merged.pivot_table(index=["scene", "spp"], columns="entry", values="ratio").to_markdown(floatfmt=".3f"))


if __name__ == "__main__":
    main()
