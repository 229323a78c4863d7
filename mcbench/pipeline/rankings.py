"""The work behind ``workflow/rules/rankings.smk``: the ranking tables (Zheng et al. 2021 Table 3
layout), the extra methods' tables, the scene table with reference noise floors, the gallery.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import re
from pathlib import Path


from mcbench import METRICS_COLUMNS, BenchError
from mcbench.contracts.scene import scene_spec
from mcbench.io.exr import check_finite, check_resolution, read_layers, read_metadata, recorded_spp
from mcbench.io.tables import read_table, write_csv, write_text
from mcbench.pipeline.registry import load_metric

if TYPE_CHECKING:  # pandas is imported inside the steps that build tables
    import pandas as pd


def unrankable_from_scene_table(metrics: pd.DataFrame, scenes_csv: str | None, *, pool: list[str]
                                ) -> dict[int, list[tuple[str, float]]]:
    """The spp columns the references cannot rank
    (:func:`mcbench.analysis.scene_summary.unrankable_columns`), from the scene table's floors
    (``reference_relmse``, empty where unknown) and the relMSE of ``pool`` (the ranked candidates
    without the noisy input). No scene table: nothing marked."""
    import pandas as pd

    from mcbench.analysis.scene_summary import column_floor_ratios, unrankable_columns

    if scenes_csv is None:
        return {}
    scenes = read_table(scenes_csv, columns=["scene", "reference_relmse"])
    floors = {str(scene): (None if pd.isna(floor) else float(floor))
              for scene, floor in zip(scenes["scene"], scenes["reference_relmse"])}
    return unrankable_columns(column_floor_ratios(metrics, floors, candidates=pool))


def write_rankings(metrics_csv: str, metric: str, csv_path: str, md_path: str, *,
                   entries: list[str], labels: dict[str, str], tex_path: str | None = None,
                   order: list[str] | None = None, note: str = "", scenes_csv: str | None = None,
                   noisy: str = "noisy") -> pd.DataFrame:
    """Score-and-rank table (Zheng et al. Table 3 layout) for one metric, as CSV and Markdown,
    and as a LaTeX booktabs table at ``tex_path`` when given (label ``tab:ranking-<metric>``).

    ``entries`` (the ranking pool's candidates and the noisy input) are the rows ranked: rows of
    other candidates (the extra methods, ranked in their own tables) are left out; a metrics table
    missing one of ``entries``, or any incomplete case, stops here instead of being ranked. ``order``: the rows'
    order (the pool's ID order; default best Avg. first). ``note``: a sentence for the Markdown
    (e.g. that the pool is partial, so the scores are on another scale than the paper's).
    ``scenes_csv``: the scene table, whose reference floors mark with ``‡`` the spp columns the
    references cannot rank (:func:`unrankable_from_scene_table`; the CSV is not marked)."""
    from mcbench.analysis.ranking import check_complete, format_latex, format_markdown, ranking_table
    from mcbench.analysis.scene_summary import unrankable_note

    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    # the ranking pool: the comparison methods' rows are ranked in their own tables
    metrics = metrics[metrics["entry"].isin(entries)]
    check_complete(metrics[metrics["metric"] == metric], entries=entries, metric_names=[metric],
                   source=metrics_csv)
    table = ranking_table(metrics, metric, order=order)
    write_csv(csv_path, table.reset_index(), float_format="%.4f")
    n_cases = metrics[metrics["metric"] == metric].groupby(["scene", "spp"]).ngroups
    n_entries = table.shape[0]
    scoring = (f"Scores per Zheng et al. 2021 Sec. 5.3.3: in each of the "
               f"{n_cases} test cases the {n_entries} entries (candidates and the noisy input) get "
               f"linearly spaced scores from {n_entries} (lowest error) to 1; columns are the mean over "
               f"scenes per spp, `Avg.` the mean over spp. Higher is better.")
    marked = unrankable_from_scene_table(metrics, scenes_csv, pool=[e for e in entries if e != noisy])
    shown_note = f"\n\n{note}" if note else ""
    floor_note = f"\n\n{unrankable_note(marked)}" if marked else ""
    write_text(md_path, f"# Ranking by {metric}\n\n{scoring}{shown_note}\n\n"
               + format_markdown(table, labels, marked=marked) + floor_note + "\n")
    if tex_path is not None:
        caption = (f"Ranking by {load_metric(metric).label}. " + scoring.replace("`", "")
                   + " Best per column in bold." + (" " + unrankable_note(marked).replace("`", "") if marked else ""))
        write_text(tex_path, format_latex(table, labels, caption=caption, label=f"tab:ranking-{metric}",
                                          marked=marked))
    return table


def write_extras_rankings(metrics_csv: str, metric: str, csv_path: str, md_path: str, *, pool: list[str],
                          extras: list[str], labels: dict[str, str], tex_path: str | None = None,
                          scenes_csv: str | None = None, noisy: str = "noisy") -> pd.DataFrame:
    """The extra methods' scores (:func:`mcbench.analysis.ranking.extras_table`): each method outside the
    ranking pool scored in a pool that adds it alone to ``pool`` (the candidates and the noisy
    input), as CSV, Markdown and LaTeX (label ``tab:extras-<metric>``). No extras: a table with a
    sentence saying so. ``scenes_csv`` marks the columns as :func:`write_rankings` does (by the
    pool's best relMSE)."""
    from mcbench.analysis.ranking import extras_table, format_latex, format_markdown
    from mcbench.analysis.scene_summary import unrankable_note

    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    table = extras_table(metrics, metric, pool=list(pool), extras=list(extras))
    write_csv(csv_path, table.reset_index(), float_format="%.4f")
    entries = len(pool) + 1
    scoring = (f"Each method outside the ranking pool is scored in a pool that adds it alone to the "
               f"{len(pool)} entries of the main table (candidates and the noisy input): in each test case the "
               f"{entries} entries get scores from {entries} (lowest error) to 1, and the row is the method's own "
               f"score (Zheng et al. 2021 Sec. 5.3.3), so the main table never depends on these methods.")
    marked = unrankable_from_scene_table(metrics, scenes_csv, pool=[c for c in pool if c != noisy]) if len(table) else {}
    floor_note = f"\n\n{unrankable_note(marked)}" if marked else ""
    body = (format_markdown(table, labels, marked=marked) + floor_note if len(table)
            else "No method outside the ranking pool in this config.")
    label = load_metric(metric).label
    write_text(md_path, f"# Extra methods by {label}\n\n{scoring}\n\n{body}\n")
    if tex_path is not None:
        text = (format_latex(table, labels, caption=f"Extra methods by {label}. "
                             + scoring + " Best per column in bold."
                             + (" " + unrankable_note(marked).replace("`", "") if marked else ""),
                             label=f"tab:extras-{metric}", marked=marked)
                if len(table) else "% No method outside the ranking pool in this config.\n")
        write_text(tex_path, text)
    return table


def _benchmark_cpu_hours(paths: list[str]) -> float:
    """Sum of Snakemake benchmark ``cpu_time`` (seconds, last repeat) over TSVs, in hours."""
    total = 0.0
    for path in paths:
        frame = read_table(path, sep="\t", columns=["cpu_time"])
        if not len(frame):
            raise BenchError(f"{path}: benchmark record without a cpu_time row")
        total += float(frame["cpu_time"].iloc[-1])
    return total / 3600.0


def _records_of(scene: str, paths: list[str]) -> list[str]:
    """The benchmark records of ``scene`` among ``paths`` (file names ``<scene>_spp<N>.tsv`` /
    ``<scene>_chunk<K>.tsv``)."""
    return [p for p in paths if re.fullmatch(rf"{re.escape(scene)}_(spp|chunk)\d+\.tsv", Path(p).name)]


def write_scene_table(metrics_csv: str, reference_paths: dict[str, str], reference_spp: dict[str, int],
                      csv_path: str, md_path: str, *, noisy_records: list[str],
                      reference_records: list[str], tex_path: str | None = None) -> pd.DataFrame:
    """Scene table with reference noise floors and render costs.

    A reference's spp is the one its header records (a stored reference keeps its own, which the
    config does not set); ``reference_spp`` (the plan's) only where the header records none (an
    imported reference). Render costs come from the Snakemake ``benchmark:`` records of the noisy
    render jobs (``noisy_records``) and reference chunk jobs (``reference_records``), inputs of the
    rule: a reference taken from the store cost this run no chunk, so 0.
    """

    from mcbench.analysis.scene_summary import reference_relmse_floor, scene_latex, scene_markdown, scene_rows
    from mcbench.pipeline.registry import load_scene

    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    floors, info, costs = {}, {}, {}
    for scene, path in reference_paths.items():
        meta = read_metadata(path)
        # a reference imported without its variance (scenes/<name>.yaml) has no known floor
        imported_without_variance = (bool(meta.get("imported_from"))
                                     and "variance" not in meta.get("layers", "").split(","))
        layers = read_layers(path, ["color"] if imported_without_variance else ["color", "variance"])
        check_finite(path, layers)
        check_resolution(path, layers["color"].shape)
        floors[scene] = None if imported_without_variance else reference_relmse_floor(layers["color"], layers["variance"])
        spec = scene_spec(load_scene(scene))
        info[scene] = {"category": spec.category, "description": spec.description,
                       "resolution": meta.get("resolution", ""),
                       "reference_spp": recorded_spp(meta) or reference_spp[scene]}
        costs[scene] = {
            "render_cpu_hours": _benchmark_cpu_hours(_records_of(scene, noisy_records)),
            "reference_cpu_hours": _benchmark_cpu_hours(_records_of(scene, reference_records)),
        }
    table = scene_rows(metrics, floors, info, costs)
    write_csv(csv_path, table, float_format="%.6g")
    write_text(md_path, scene_markdown(table))
    if tex_path is not None:
        write_text(tex_path, scene_latex(table, caption="Test scenes: reference spp and the reference's estimated "
                                                        "relMSE against the noisy and best candidate's relMSE at the "
                                                        "highest spp; a floor ratio below 10 (bold) means the "
                                                        "reference is too noisy to rank there."))
    return table


def write_gallery(reference_paths: dict[str, str], png_path: str) -> None:
    """Gallery of all references with their names (Fig. 3 of Zheng et al.)."""
    from mcbench.analysis.scene_summary import gallery_figure

    references = {}
    for scene, path in reference_paths.items():
        layers = read_layers(path, ["color"])
        check_finite(path, layers)
        references[scene] = layers["color"]
    gallery_figure(references, png_path)
