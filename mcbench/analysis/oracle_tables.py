"""Tables and the weight-map figure of the oracle study (Zheng et al. 2021 Sec. 5.2.7, Fig. 11):
relMSE and DSSIM of each weighting against the reference, as a DataFrame and a Markdown table,
and a PNG of the weight maps (weights from :mod:`mcbench.combine.oracle_weights`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench.analysis.metrics import dssim, relmse
from mcbench.combine.oracle_weights import UNCONSTRAINED_RANGE

__all__ = ["error_table", "table_markdown", "weight_maps_figure"]


def error_table(images: dict[str, np.ndarray], reference, *, rows: dict[str, dict]) -> pd.DataFrame:
    """relMSE and DSSIM (:mod:`mcbench.analysis.metrics`) of each image against ``reference``.

    ``images``: {name: (H, W, 3)}; ``rows``: {name: {column: value}} extra columns per image
    (e.g. panel, statistics, weights), in the table's row order. Returns a DataFrame with
    columns ``name``, the extra columns, ``relmse``, ``dssim``."""
    records = []
    for name, extra in rows.items():
        image = images[name]
        records.append({"name": name, **extra, "relmse": relmse(image, reference), "dssim": dssim(image, reference)})
    return pd.DataFrame.from_records(records)


def table_markdown(table: pd.DataFrame, *, title: str, digits: int = 5) -> str:
    """A pipe table of ``table`` (floats with ``digits`` significant digits) under ``title``."""
    def cell(value):
        return f"{value:.{digits}g}" if isinstance(value, float) else str(value)

    lines = [f"**{title}**", "", "| " + " | ".join(table.columns) + " |",
             "| " + " | ".join("---" for _ in table.columns) + " |"]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in table.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def weight_maps_figure(maps: dict[str, np.ndarray], path, *, denoisers: list[str], title: str) -> None:
    """PNG of weight maps (channels averaged): one row per denoiser, one column per variant.

    ``maps``: {column title: (N, H, W, C) weights}, N = len(``denoisers``). Columns whose weights
    all lie in [0, 1] (one-hot, simplex) share a [0, 1] colour scale; the others (unconstrained)
    share a diverging one centred at 0.5 on [-1, 2] (:data:`UNCONSTRAINED_RANGE`; values beyond
    are clipped, so broken weights saturate). Written atomically."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mcbench.analysis.error_speed_figures import save_figure

    averaged = {name: np.asarray(w, np.float64).mean(axis=-1) for name, w in maps.items()}
    bounded = {name: bool(a.min() >= -1e-9 and a.max() <= 1.0 + 1e-9) for name, a in averaged.items()}
    low, high = UNCONSTRAINED_RANGE
    scales = {True: dict(cmap="viridis", vmin=0.0, vmax=1.0), False: dict(cmap="RdBu_r", vmin=low, vmax=high)}
    rows, cols = len(denoisers), len(maps)
    figure, axes = plt.subplots(rows, cols, figsize=(1.7 * cols + 1.6, 1.7 * rows + 1.2), squeeze=False)
    shown = {}
    for j, (name, weights) in enumerate(averaged.items()):
        for i, denoiser in enumerate(denoisers):
            axis = axes[i, j]
            shown[bounded[name]] = axis.imshow(weights[i], interpolation="nearest", **scales[bounded[name]])
            axis.set_xticks([])
            axis.set_yticks([])
            if i == 0:
                axis.set_title("\n".join(textwrap.wrap(name, 18)), fontsize=7)
            if j == 0:
                axis.set_ylabel(denoiser, fontsize=8)
    for is_bounded, image in shown.items():
        figure.colorbar(image, ax=axes, shrink=0.7, pad=0.02,
                        label="weight in [0, 1]" if is_bounded else f"unconstrained weight (clipped to [{low:g}, {high:g}])")
    figure.suptitle("\n".join(textwrap.wrap(title, 120)), fontsize=8)
    save_figure(figure, path)
