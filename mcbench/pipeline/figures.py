"""The work behind ``workflow/rules/figures.smk``: error against spp, and speed against error.
"""

from __future__ import annotations



from mcbench import METRICS_COLUMNS
from mcbench.io.tables import read_table


def write_error_curves(metrics_csv: str, metric: str, png_path: str, *, labels: dict[str, str],
                       entries: list[str] | None = None) -> None:
    """Error against spp of every entry (or of ``entries`` only), per scene and averaged, for one
    metric (mcbench.analysis.error_speed_figures, like Fig. 13 of Zheng et al.); ``labels``: entry
    -> legend label."""
    from mcbench.analysis.error_speed_figures import error_curves, error_curves_figure

    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    if entries is not None:
        metrics = metrics[metrics["entry"].isin(entries)]
    error_curves_figure(error_curves(metrics, metric=metric), png_path, metric=metric, labels=labels)


def write_speed_error(metrics_csv: str, timings_csv: str, png_path: str, *, metric: str,
                      labels: dict[str, str], inputs: dict[str, list[str]]) -> None:
    """Each method's mean compute time (timings.csv; a combiner's with the ``inputs`` it takes)
    against its mean ``metric`` error (metrics.csv), as a labelled log-log scatter."""
    from mcbench.analysis.error_speed_figures import speed_error_figure, speed_error_points

    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    timings = read_table(timings_csv, columns=["scene", "spp", "method", "seconds"])
    points = speed_error_points(metrics, timings, metric=metric, inputs=inputs)
    speed_error_figure(points, png_path, metric=metric, labels=labels)
