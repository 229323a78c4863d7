"""Scene-level reports: the reference noise floor, the scene table and the gallery figure.

Reference noise floor. A reference r̂ rendered with n samples has per-pixel variance of the
mean Var[r̂] (stored in the reference EXR). Measured against it, any candidate's relMSE carries
an extra E[(r̂ - r)²] / (r² + 0.01) ≈ Var[r̂] / (r̂² + 0.01) per pixel-channel; its mean over
the image, :func:`reference_relmse_floor`, is the reference's estimated relMSE. A ranking is
trustworthy when the best candidate's relMSE at the highest spp is at least 10× above it.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from mcbench.analysis.metrics import RELMSE_EPSILON, tonemap

FLOOR_RATIO_REQUIRED = 10.0


class ReferenceNoiseWarning(UserWarning):
    """A reference is too noisy to rank candidates at the highest spp."""


def reference_relmse_floor(color: np.ndarray, variance: np.ndarray) -> float:
    """Estimated relMSE of a reference from its variance of the mean: mean of Var / (r² + 0.01).

    color, variance: (H, W, 3) linear radiance and its per-pixel, per-channel variance.
    """
    color = np.asarray(color, dtype=np.float64)
    variance = np.maximum(np.asarray(variance, dtype=np.float64), 0.0)
    return float(np.mean(variance / (color * color + RELMSE_EPSILON)))


def scene_rows(metrics: pd.DataFrame, floors: dict[str, float], scenes_info: dict[str, dict],
               costs: dict[str, dict], noisy: str = "noisy") -> pd.DataFrame:
    """One row per scene: category, description, reference spp and noise floor, the noisy and
    best candidate's relMSE at the highest spp, their ratio to the floor, and render costs.

    ``costs[scene]`` holds ``render_cpu_hours`` and ``reference_cpu_hours``. A floor of None (a
    reference imported without its variance) is unknown: ``reference_relmse`` and ``floor_ratio``
    are NaN there, written "n/a", and no warning is raised for it.
    """
    relmse = metrics[metrics["metric"] == "relmse"]
    rows = []
    for scene, info in scenes_info.items():
        cases = relmse[relmse["scene"] == scene]
        top_spp = int(cases["spp"].max())
        top = cases[cases["spp"] == top_spp].set_index("entry")["value"]
        candidates = top.drop(index=noisy, errors="ignore")
        best = candidates.idxmin()
        floor = floors[scene]
        if floor is None:
            floor, ratio = math.nan, math.nan
        else:
            ratio = float(candidates.min()) / floor if floor > 0 else math.inf
        rows.append({
            "scene": scene, "category": info.get("category", ""), "description": info.get("description", ""),
            "resolution": info.get("resolution", ""), "integrator": info.get("integrator", ""),
            "reference_spp": info.get("reference_spp", ""), "reference_relmse": floor,
            "top_spp": top_spp, "noisy_relmse": float(top.get(noisy, np.nan)),
            "best_candidate": best, "best_relmse": float(candidates.min()), "floor_ratio": ratio,
            "floor_ok": bool(math.isnan(ratio) or ratio >= FLOOR_RATIO_REQUIRED),
            "render_cpu_hours": costs.get(scene, {}).get("render_cpu_hours", np.nan),
            "reference_cpu_hours": costs.get(scene, {}).get("reference_cpu_hours", np.nan),
        })
    table = pd.DataFrame(rows)
    for row in table[~table["floor_ok"]].itertuples():
        warnings.warn(f"scene '{row.scene}': reference noise floor (relMSE {row.reference_relmse:.3g}) is only "
                      f"{row.floor_ratio:.1f}x below the best candidate at {row.top_spp} spp "
                      f"({row.best_candidate}, {row.best_relmse:.3g}); render the reference with more spp",
                      ReferenceNoiseWarning, stacklevel=2)
    return table


def column_floor_ratios(metrics: pd.DataFrame, floors: dict[str, float | None], *,
                        candidates: list[str]) -> pd.DataFrame:
    """Per test case (scene, spp): the best of ``candidates``' relMSE over the scene's reference
    floor (:func:`reference_relmse_floor`), the ratio :func:`scene_rows` gives for the highest spp
    only.

    ``metrics``: tidy table (scene, spp, entry, metric, value); only ``relmse`` rows of
    ``candidates`` are read (pass the ranking pool without the noisy input). ``floors`` maps each
    scene to its floor, None where unknown (a reference imported without variance). Returns columns
    scene, spp, best_candidate, best_relmse, reference_relmse, floor_ratio (NaN where the floor is
    unknown, inf where it is 0), sorted by scene and spp. A scene of ``metrics`` without a floor
    raises ``ValueError`` naming it.
    """
    relmse = metrics[(metrics["metric"] == "relmse") & metrics["entry"].isin(list(candidates))]
    rows = []
    for (scene, spp), case in relmse.groupby(["scene", "spp"], sort=True):
        if scene not in floors:
            raise ValueError(f"no reference floor for scene '{scene}': pass every scene of the metrics in floors")
        values = case.set_index("entry")["value"].astype(np.float64)
        floor = floors[scene]
        best = float(values.min())
        if floor is None:
            ratio, floor = math.nan, math.nan
        else:
            ratio = best / floor if floor > 0 else math.inf
        rows.append({"scene": str(scene), "spp": int(spp), "best_candidate": str(values.idxmin()),
                     "best_relmse": best, "reference_relmse": floor, "floor_ratio": ratio})
    return pd.DataFrame(rows, columns=["scene", "spp", "best_candidate", "best_relmse", "reference_relmse",
                                       "floor_ratio"])


def unrankable_columns(ratios: pd.DataFrame, *, required: float = FLOOR_RATIO_REQUIRED
                       ) -> dict[int, list[tuple[str, float]]]:
    """The spp columns of a ranking table that the references cannot rank: each spp at which some
    scene's floor ratio (:func:`column_floor_ratios`) is below ``required``, mapped to those
    (scene, ratio) pairs, lowest ratio first. Unknown floors (NaN) mark nothing."""
    marked: dict[int, list[tuple[str, float]]] = {}
    low = ratios[ratios["floor_ratio"] < required]
    for spp, rows in low.groupby("spp", sort=True):
        rows = rows.sort_values("floor_ratio", kind="stable")
        marked[int(spp)] = [(str(s), float(r)) for s, r in zip(rows["scene"], rows["floor_ratio"])]
    return marked


#: The mark of a ranking column that the references cannot rank (:func:`unrankable_columns`).
UNRANKABLE_MARK = "‡"


def unrankable_note(marked: dict[int, list[tuple[str, float]]], *, required: float = FLOOR_RATIO_REQUIRED) -> str:
    """One Markdown paragraph explaining the ``‡`` columns of a ranking table ('' when none)."""
    if not marked:
        return ""
    parts = [f"{spp} spp ({', '.join(f'{scene} {ratio:.1f}×' for scene, ratio in scenes)})"
             for spp, scenes in marked.items()]
    return (f"{UNRANKABLE_MARK} Columns the references cannot rank: in each, some scene's reference noise floor "
            f"(its own estimated relMSE, `tables/scenes.md`) is less than {required:g}× below the best ranked "
            f"candidate's relMSE, so the reference's noise can reorder the column (docs/measurements.md: ranks "
            f"moved by a 4× cleaner reference): " + "; ".join(parts) + ".")


def scene_markdown(table: pd.DataFrame) -> str:
    """The scene table as Markdown, saying plainly which references are too noisy."""
    shown = table[["scene", "category", "reference_spp", "reference_relmse", "noisy_relmse", "best_candidate",
                   "best_relmse", "floor_ratio", "render_cpu_hours", "reference_cpu_hours", "description"]].copy()
    shown["floor_ratio"] = ["n/a" if math.isnan(r) else f"{r:.1f}" + ("" if r >= FLOOR_RATIO_REQUIRED else " ⚠ <10×")
                            for r in table["floor_ratio"]]
    for column in ("reference_relmse", "noisy_relmse", "best_relmse"):
        shown[column] = ["n/a" if math.isnan(v) else f"{v:.3g}" for v in table[column]]
    shown["reference_spp"] = ["n/a" if v is None or v != v else v for v in table["reference_spp"]]
    for column in ("render_cpu_hours", "reference_cpu_hours"):
        shown[column] = [f"{v:.4f}" for v in table[column]]
    top = int(table["top_spp"].max()) if len(table) else 0
    bad = table[~table["floor_ok"]]["scene"].tolist()
    verdict = ("Every reference's noise floor is at least 10× below the best candidate's relMSE."
               if not bad else f"**Too noisy to rank at the highest spp: {', '.join(bad)}** "
                               f"(reference floor within 10× of the best candidate's relMSE).")
    return (f"# Scenes\n\n`reference_relmse` is the reference's own estimated relMSE (mean of Var/(r²+0.01) "
            f"from its stored variance); `noisy_relmse` and `best_relmse` are measured at {top} spp; "
            f"`floor_ratio` = best_relmse / reference_relmse. CPU-hours are Snakemake's measured CPU time "
            f"of the render jobs (all spp levels) and of the reference chunks (0 for a reference taken from "
            f"the store).\n\n{verdict}\n\n"
            + shown.to_markdown(index=False) + "\n")


def scene_latex(table: pd.DataFrame, *, caption: str, label: str = "tab:scenes") -> str:
    """The scene table as a LaTeX ``table`` with booktabs rules (``\\usepackage{booktabs}``): scene,
    category, reference spp, the reference's estimated relMSE, the noisy and best candidate's relMSE
    at the highest spp and their floor ratio; a ratio below 10 (a reference too noisy to rank) is
    bold. Text is escaped with :func:`mcbench.analysis.ranking.latex_escape`."""
    from mcbench.analysis.ranking import latex_escape

    header = ["Scene", "Category", "Ref. spp", "Ref. relMSE", "Noisy relMSE", "Best", "Best relMSE", "Floor ratio"]
    rows = []
    for row in table.itertuples():
        ratio = "n/a" if math.isnan(row.floor_ratio) else f"{row.floor_ratio:.1f}"
        unknown_spp = row.reference_spp is None or row.reference_spp != row.reference_spp
        cells = [latex_escape(row.scene), latex_escape(row.category), "n/a" if unknown_spp else str(row.reference_spp),
                 "n/a" if math.isnan(row.reference_relmse) else f"{row.reference_relmse:.3g}", f"{row.noisy_relmse:.3g}", latex_escape(row.best_candidate),
                 f"{row.best_relmse:.3g}", ratio if row.floor_ok else rf"\textbf{{{ratio}}}"]
        rows.append("    " + " & ".join(cells) + r" \\")
    lines = [r"% Requires \usepackage{booktabs}. Written by mcbench (mcbench.analysis.scene_summary.scene_latex).",
             r"\begin{table}", r"  \centering", rf"  \caption{{{latex_escape(caption)}}}", rf"  \label{{{label}}}",
             r"  \begin{tabular}{llrrrlrr}", r"    \toprule", "    " + " & ".join(header) + r" \\", r"    \midrule",
             *rows, r"    \bottomrule", r"  \end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def gallery_figure(references: dict[str, np.ndarray], path: str | Path, columns: int = 6) -> None:
    """A grid of tone-mapped references with their names (like Fig. 3 of Zheng et al.)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mcbench.analysis.error_speed_figures import save_figure

    names = list(references)
    columns = max(1, min(columns, len(names)))
    rows = math.ceil(len(names) / columns)
    figure, axes = plt.subplots(rows, columns, figsize=(2.2 * columns, 2.4 * rows), squeeze=False)
    for axis in axes.ravel():
        axis.axis("off")
    for axis, name in zip(axes.ravel(), names):
        axis.imshow(tonemap(references[name]), interpolation="nearest")
        axis.set_title(name.replace("_", " "), fontsize=8)
    figure.tight_layout()
    save_figure(figure, path, dpi=100)
