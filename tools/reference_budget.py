"""Per-scene reference spp from the measured noise floors: where to spend a reference budget.

    python tools/reference_budget.py results/tables/scenes.csv --budget-core-minutes 30

Reads the scene table of a finished run (``floor_ratio``: the best candidate's relMSE at the highest
spp over the reference's own estimated relMSE; ``reference_spp``; ``reference_cpu_hours``: the
measured CPU time of the scene's reference chunks). A reference's floor f falls as 1/spp and its
cost grows as spp. The best candidate's relMSE measured against a reference is its error against
the truth plus that reference's floor (the term the corrected relMSE removes), so with the measured
ratio R = (e + f) / f the error is e = (R - 1) f, and a reference of k times the spp gives the ratio
1 + (R - 1) k: doubling the spp of a scene measured at ratio 1.6 gives 2.2, not 3.2
(docs/measurements.md measured 1.6 -> 3.4 for 4x on veach_ajar, this model 3.4).
Greedy, lowest ratio first: double the spp of the scene whose ratio is lowest and below
``--required`` (10, the scene table's rule), while the added CPU stays within the budget; a scene
whose next doubling does not fit is left. Prints, per scene, the measured ratio, the spp and ratio
after, the added core-minutes, and the ``reference: scene_spp:`` block for a config file.

    python tools/reference_budget.py R/tables/scenes.csv --fit 10.5 --max-spp 147456 \
        --cap-spp veach_ajar=65536,fog_beams=65536 --columns R/metrics.csv R/tables/ranking_relmse.csv

``--fit T`` instead gives every scene the least spp (a multiple of ``--step``) whose predicted
ratio reaches T, from floors measured at any spp (best from a run on the reference store, whose
floors are measured at its high spp): fewer samples where the measured floor leaves room, more
where it is short. A scene that would need more than ``--max-spp`` gets at most its ``--cap-spp``
(the spp the config gave it: no budget is spent on a ratio it cannot reach, its highest columns
stay marked ‡), and with ``--columns <metrics.csv> <ranking csv>`` of the same run only as much as
keeps ranked, at T, every spp column that its cap ranks. ``--cost-per-kspp scene=seconds,...``
(CPU seconds per 1024 spp, measured) adds the CPU of each scene's reference at the spp after.
"""

from __future__ import annotations

import argparse
import math

import pandas as pd


def plan(scenes: pd.DataFrame, *, budget_core_seconds: float, required: float = 10.0) -> pd.DataFrame:
    """Doublings of reference spp, lowest floor ratio first, within the budget (see the module)."""
    table = scenes[["scene", "reference_spp", "floor_ratio", "reference_cpu_hours"]].copy()
    table["spp_after"] = table["reference_spp"].astype(int)
    table["ratio_after"] = table["floor_ratio"].astype(float)
    table["added_core_seconds"] = 0.0
    left = float(budget_core_seconds)
    while True:
        open_rows = table[(table["ratio_after"] < required) & table["ratio_after"].notna()]
        if open_rows.empty:
            break
        index = open_rows["ratio_after"].idxmin()
        row = table.loc[index]
        cost_now = float(row["reference_cpu_hours"]) * 3600.0 * row["spp_after"] / row["reference_spp"]
        if not math.isfinite(cost_now) or cost_now > left:
            table.loc[index, "ratio_after"] = math.nan   # cannot afford: leave this scene
            table.loc[index, "left_out"] = True
            continue
        left -= cost_now
        table.loc[index, "spp_after"] = int(row["spp_after"]) * 2
        table.loc[index, "ratio_after"] = _ratio(float(row["floor_ratio"]), int(row["spp_after"]) * 2 / row["reference_spp"])
        table.loc[index, "added_core_seconds"] = float(row["added_core_seconds"]) + cost_now
    # a scene left out shows the ratio its last affordable spp gives
    stopped = table["ratio_after"].isna() & table["floor_ratio"].notna()
    table.loc[stopped, "ratio_after"] = [_ratio(r, k) for r, k in zip(
        table.loc[stopped, "floor_ratio"], table.loc[stopped, "spp_after"] / table.loc[stopped, "reference_spp"])]
    return table


def fit(scenes: pd.DataFrame, *, target: float, step: int = 1024, max_spp: int,
        cap_spp: dict[str, int], columns: pd.DataFrame | None = None) -> pd.DataFrame:
    """Per scene the least multiple of ``step`` whose predicted floor ratio (:func:`_ratio`) at the
    highest spp reaches ``target``. A scene that would need more than ``max_spp`` takes its
    ``cap_spp``, or less: the least spp that keeps every spp column it ranks at ``cap_spp`` (ratio
    at least ``target`` in ``columns``: scene, spp, floor_ratio, measured with the references of
    ``scenes``) at ``target``; without ``columns``, ``cap_spp`` itself. Columns: scene,
    reference_spp, floor_ratio, spp_after, ratio_after (highest spp), reached, ranked_up_to (the
    highest spp column the scene still ranks at ``target``; its own spp when it reaches ``target``)."""
    table = scenes[["scene", "reference_spp", "floor_ratio"]].copy()
    spp_after, ratio_after, reached, ranked = [], [], [], []
    for row in table.itertuples():
        if not math.isfinite(row.floor_ratio) or row.floor_ratio <= 1.0:
            raise ValueError(f"scene {row.scene!r}: floor ratio {row.floor_ratio} cannot be extrapolated (needs > 1)")
        spp = _least_spp(row.floor_ratio, row.reference_spp, target, step)
        top = None
        if spp > max_spp:
            if row.scene not in cap_spp:
                raise ValueError(f"scene {row.scene!r} needs {spp} spp (> --max-spp {max_spp}); give its --cap-spp")
            spp = int(cap_spp[row.scene])
            if columns is not None:
                own = columns[columns["scene"] == row.scene]
                factor = spp / row.reference_spp
                kept = own[[_ratio(r, factor) >= target for r in own["floor_ratio"]]]
                if not kept.empty:
                    binding = kept.loc[kept["floor_ratio"].idxmin()]
                    spp = min(spp, _least_spp(float(binding["floor_ratio"]), row.reference_spp, target, step))
                    top = int(kept["spp"].astype(int).max())
        spp_after.append(spp)
        ratio_after.append(_ratio(float(row.floor_ratio), spp / row.reference_spp))
        reached.append(ratio_after[-1] >= target)
        ranked.append(top)
    table["spp_after"], table["ratio_after"], table["reached"] = spp_after, ratio_after, reached
    table["ranked_up_to"] = pd.Series(ranked, index=table.index, dtype=object)
    return table


def _least_spp(measured_ratio: float, measured_spp: int, target: float, step: int) -> int:
    """The least multiple of ``step`` at which a ratio ``measured_ratio`` at ``measured_spp``
    becomes ``target`` (:func:`_ratio` solved for the factor)."""
    factor = (target - 1.0) / (measured_ratio - 1.0)
    return max(step, math.ceil(factor * measured_spp / step - 1e-9) * step)


def _ratio(measured: float, factor: float) -> float:
    """The floor ratio with ``factor`` times the reference spp, from the ``measured`` one (module)."""
    return 1.0 + (measured - 1.0) * factor


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes_csv")
    parser.add_argument("--budget-core-minutes", type=float)
    parser.add_argument("--required", type=float, default=10.0)
    parser.add_argument("--fit", type=float, metavar="T", help="the least spp reaching floor ratio T per scene")
    parser.add_argument("--step", type=int, default=1024)
    parser.add_argument("--max-spp", type=int, default=2 ** 31)
    parser.add_argument("--cap-spp", default="", help="scene=spp,... for the scenes above --max-spp")
    parser.add_argument("--columns", nargs=2, metavar=("METRICS_CSV", "RANKING_CSV"),
                        help="the same run's metrics.csv and a ranking table: per-column floor ratios")
    parser.add_argument("--cost-per-kspp", default="", help="scene=CPU seconds per 1024 spp,...")
    args = parser.parse_args(argv)
    if args.fit is not None:
        return _print_fit(args)
    if args.budget_core_minutes is None:
        parser.error("give --budget-core-minutes (doublings within a budget) or --fit T")
    table = plan(pd.read_csv(args.scenes_csv), budget_core_seconds=60.0 * args.budget_core_minutes,
                 required=args.required)
    print("| scene | reference spp | floor ratio | spp after | ratio after | added core-min |")
    print("|---|---|---|---|---|---|")
    for row in table.itertuples():
        print(f"| {row.scene} | {row.reference_spp} | {row.floor_ratio:.1f} | {row.spp_after} | "
              f"{row.ratio_after:.1f} | {row.added_core_seconds / 60:.1f} |")
    print(f"\nadded: {table['added_core_seconds'].sum() / 60:.1f} core-minutes of {args.budget_core_minutes:g}\n")
    print("reference:\n  scene_spp:")
    for row in table.itertuples():
        if row.spp_after != row.reference_spp:
            print(f"    {row.scene}: {row.spp_after}")
    return 0



def _pairs(text: str) -> dict[str, float]:
    return {k.strip(): float(v) for k, v in (item.split("=") for item in text.split(",") if item.strip())}


def _print_fit(args) -> int:
    cap = {k: int(v) for k, v in _pairs(args.cap_spp).items()}
    cost = _pairs(args.cost_per_kspp)
    scenes = pd.read_csv(args.scenes_csv)
    columns = None
    if args.columns:
        from mcbench.analysis.scene_summary import column_floor_ratios

        metrics, ranking = (pd.read_csv(path) for path in args.columns)
        columns = column_floor_ratios(metrics, dict(zip(scenes["scene"], scenes["reference_relmse"])),
                                      candidates=list(ranking["candidate"]))
    table = fit(scenes, target=args.fit, step=args.step, max_spp=args.max_spp, cap_spp=cap, columns=columns)
    print("| scene | measured at spp | floor ratio | spp after | predicted ratio | reaches target | ranks up to | CPU min |")
    print("|---|---:|---:|---:|---:|---|---:|---:|")
    total = 0.0
    for row in table.itertuples():
        minutes = cost[row.scene] * row.spp_after / 1024 / 60 if row.scene in cost else math.nan
        total += minutes
        ranks = "all" if row.reached else (f"{row.ranked_up_to} spp" if row.ranked_up_to else "?")
        print(f"| {row.scene} | {row.reference_spp} | {row.floor_ratio:.1f} | {row.spp_after} | "
              f"{row.ratio_after:.1f} | {'yes' if row.reached else 'no'} | {ranks} | {minutes:.1f} |")
    print(f"\nCPU of the references: {total:.1f} core-minutes\n")
    print("reference:\n  scene_spp:")
    for row in table.itertuples():
        print(f"    {row.scene}: {row.spp_after}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
