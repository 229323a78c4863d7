"""The comparisons of Zheng et al. 2021 Sec. 5.2 as tables: Tables 1-2 (the ensemble against
one-hot selection), the ablation table (Sec. 5.2.1-5.2.5) and a ranking of the comparison
methods beside the full ensembles they belong to. Pure functions over the tidy metrics table
(columns scene, spp, entry, metric, value), the timings table (scene, spp, method, seconds)
and the method table (name -> {module, kind, inputs, params, label, comparison_role}); core: no
plugin import, no plugin name: a method's role is the ``comparison_role`` its declaration sets
(``mcbench.contracts.method.MethodSpec``), copied into the method table by the registry.

How comparisons are found in the method table
---------------------------------------------
* A **full ensemble** is a method of role ``ensemble`` whose params set none of ``weights``,
  ``channels``, ``solver``, ``filter`` to a value other than the default (:data:`ENSEMBLE_DEFAULTS`:
  simplex, rgb, iterative, True). Changing another option of :data:`ENSEMBLE_DEFAULTS` (the
  public code's post-processing, the solver's start) makes an "ensemble variant", in no table and
  not in the pool; ``seed`` and tolerances change nothing here.
* Its **one-hot variants**: methods of role ``one-hot selection`` with the same *set* of inputs
  and ``prefilter`` sbf, nfor or post. Its **naive average**: role ``naive average``, same set.
* Its **ablations**: role ``ensemble``, same set of inputs, exactly one of the four params
  changed (:data:`ABLATIONS`: weights=unconstrained, solver=qp, solver=exact, channels=single,
  filter=False), plus its naive average (naive averaging, 5.2.5).
* Two methods in the same role of a table for the same input set are refused (one is needed).
* :func:`comparison_role` names the role of a comparison method (``None`` for base denoisers,
  full ensembles, deep combiners, anything unknown), so such methods stay out of the main ranking
  pool; an ensemble with several of the four params changed is an ``"ensemble variant"``.

Tables
------
Table 1 (2): a test case is a scene x spp x full ensemble that has both pre-filtering variants
(sbf, nfor) (the post variant); the ensemble wins when its error is lower than every variant's
(strictly). Cells are the percentage of won cases per ensemble size (number of inputs) and spp,
with the count n; ``Avg.`` pools the cases of the row/column (the paper's Avg. row is pooled:
its per-size counts differ). Full ensembles without the variants are not in the table (listed
in its note). A method of a table missing a case present in the metrics table stops with a
:class:`mcbench.BenchError` naming method and case: never a silently smaller denominator.
Every division is guarded: n = 0 gives ``None`` (empty CSV cell, "–" in Markdown).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench import METRICS_COLUMNS, BenchError
from mcbench.combine.ensemble_weights import ENSEMBLE_DEFAULTS
from mcbench.io.tables import read_table, write_csv, write_text
from mcbench.analysis.ranking import format_markdown, ranking_table

__all__ = ["ENSEMBLE_DEFAULTS", "ABLATIONS", "ONE_HOT_VARIANTS", "PAPER_AVG", "CLAIMS", "ensemble_changes",
           "comparison_role", "find_comparisons", "metric_values", "beats_cases", "beats_table",
           "beats_markdown", "ablation_cases", "ablation_table", "ablation_markdown", "comparison_ranking",
           "write_onehot_tables", "write_ablation_table", "write_comparison_ranking"]

# ENSEMBLE_DEFAULTS (mcbench.combine.ensemble_weights, re-exported): the ensemble's defaults of the
# options that change what is solved or filtered; changing one of the first four is an ablation,
# any other (the public code's post-processing, the solver's start) makes an "ensemble variant"
ONE_HOT_VARIANTS = ("sbf", "nfor", "post")
TABLE_VARIANTS = {1: ("sbf", "nfor"), 2: ("post",)}
# (param, value) -> ablation kind; the section of the paper that makes the claim.
ABLATIONS = {("weights", "unconstrained"): "unconstrained weights", ("solver", "qp"): "general QP solver",
             ("solver", "exact"): "exact solver", ("channels", "single"): "single-channel",
             ("filter", False): "unfiltered"}
NAIVE = "naive averaging"
SECTIONS = {"unconstrained weights": "5.2.1", "general QP solver": "5.2.2", "exact solver": "",
            "single-channel": "5.2.3", "unfiltered": "5.2.4", NAIVE: "5.2.5"}
# The Avg. rows of the paper's Tables 1 and 2 (relMSE, percent; spp 4..256 and overall).
PAPER_AVG = {1: {4: 85.1, 8: 80.8, 16: 78.5, 32: 76.8, 64: 71.4, 128: 68.4, 256: 63.5, "Avg.": 74.9},
             2: {4: 82.9, 8: 80.6, 16: 73.8, 32: 70.3, 64: 69.1, 128: 67.8, 256: 61.7, "Avg.": 72.3}}
WORSE = "worse"
EQUIVALENT_SLOWER = "equivalent, slower"
# kind -> (the paper's claim, the rule that decides "reproduced?" from our numbers)
CLAIMS = {
    "unconstrained weights": ("non-negativity is needed for stability: unconstrained weights give "
                              "fireflies and a dramatically increased error", WORSE),
    "general QP solver": ("visually indistinguishable, almost identical relMSE/DSSIM; the iterative "
                          "solver is ~10x faster", EQUIVALENT_SLOWER),
    "exact solver": ("not in the paper (our closed-form solver of the same problem)", None),
    "single-channel": ("channel-wise weights give a slightly lower error in both metrics", WORSE),
    "unfiltered": ("filtering the weights removes noise and edge artifacts, reduces the error", WORSE),
    NAIVE: ("the ensemble has a significantly lower error than naive averaging", WORSE),
}
RULES = {WORSE: "yes if the ablation loses (higher relMSE) in >= 50 % of cases and its mean relMSE is higher",
         EQUIVALENT_SLOWER: "yes if its mean relMSE is within 5 % of the full method's and it takes >= 5x "
                            "the full method's time", None: "n/a: no claim"}


def ensemble_changes(spec: dict) -> dict:
    """The ablation params (:data:`ENSEMBLE_DEFAULTS`) that ``spec['params']`` sets to a
    non-default value, ``{param: value}``."""
    params = spec.get("params") or {}
    return {key: params[key] for key, default in ENSEMBLE_DEFAULTS.items()
            if key in params and params[key] != default}


def comparison_role(spec: dict) -> str | None:
    """The role of a comparison method ("one-hot sbf", "naive average", "unconstrained weights",
    "ensemble variant", ...) or ``None`` for a method of the main ranking pool (base denoisers,
    full ensembles, deep combiners, anything unknown)."""
    declared = spec.get("comparison_role")
    if declared == "one-hot selection":
        return f"one-hot {(spec.get('params') or {}).get('prefilter', 'none')}"
    if declared == "naive average":
        return "naive average"
    if declared != "ensemble":
        return None
    changes = ensemble_changes(spec)
    if not changes:
        return None
    if len(changes) == 1:
        return ABLATIONS.get(next(iter(changes.items())), "ensemble variant")
    return "ensemble variant"


def find_comparisons(methods: dict[str, dict]) -> dict[str, dict]:
    """Per full ensemble (in method-table order): ``{"inputs": frozenset, "size": int,
    "one_hot": {prefilter: name}, "ablations": {kind: name}}`` (naive average as kind
    ``"naive averaging"``). Raises BenchError when two methods take one role for one input set."""
    roles: dict[tuple, str] = {}
    for name, spec in methods.items():
        role = comparison_role(spec)
        if role is None:
            continue
        inputs = frozenset(spec.get("inputs", []))
        kind = NAIVE if role == "naive average" else role
        if kind not in SECTIONS and kind not in {f"one-hot {v}" for v in ONE_HOT_VARIANTS}:
            continue  # a role no table uses ("one-hot none", "ensemble variant")
        if (inputs, kind) in roles:
            raise BenchError(f"methods '{roles[inputs, kind]}' and '{name}' are both the {role} of inputs "
                             f"{sorted(inputs)}; the comparison tables need one method per role")
        roles[inputs, kind] = name
    found = {}
    for name, spec in methods.items():
        if spec.get("comparison_role") != "ensemble" or ensemble_changes(spec):
            continue
        inputs = frozenset(spec.get("inputs", []))
        one_hot = {v: roles[inputs, f"one-hot {v}"] for v in ONE_HOT_VARIANTS if (inputs, f"one-hot {v}") in roles}
        ablations = {k: roles[inputs, k] for k in SECTIONS if (inputs, k) in roles}
        found[name] = {"inputs": inputs, "size": len(inputs), "one_hot": one_hot, "ablations": ablations}
    return found


def _cases(frame: pd.DataFrame) -> list[tuple[str, int]]:
    return sorted({(str(s), int(n)) for s, n in zip(frame["scene"], frame["spp"])})


def metric_values(frame: pd.DataFrame, metric: str | None, names: list[str], *, cases=None,
                  name_column: str = "entry", value_column: str = "value",
                  source: str = "metrics") -> pd.DataFrame:
    """Wide float64 frame, index (scene, spp) = ``cases`` (default: every case of ``frame``),
    one column per name, of the ``metric`` rows (``None``: all rows, e.g. a timings table with
    ``name_column="method"``, ``value_column="seconds"``). Raises BenchError naming the method and
    case for a missing, duplicated or non-finite value."""
    cases = _cases(frame) if cases is None else list(cases)
    rows = frame if metric is None else frame[frame["metric"] == metric]
    rows = rows[rows[name_column].isin(names)]
    what = f"{metric} value" if metric else value_column
    keys = list(zip(rows["scene"].astype(str), rows["spp"].astype(int), rows[name_column]))
    values = pd.to_numeric(rows[value_column], errors="coerce").to_numpy(dtype=np.float64)
    table: dict[tuple, float] = {}
    for key, value in zip(keys, values):
        if key in table:
            raise BenchError(f"{source}: two {what}s for method '{key[2]}' in case scene {key[0]}, spp {key[1]}")
        if not np.isfinite(value):
            raise BenchError(f"{source}: {what} of method '{key[2]}' in case scene {key[0]}, spp {key[1]} "
                             f"is missing or not finite")
        table[key] = float(value)
    for scene, spp in cases:
        for name in names:
            if (scene, spp, name) not in table:
                raise BenchError(f"{source}: no {what} for method '{name}' in case scene {scene}, spp {spp}")
    index = pd.MultiIndex.from_tuples(cases, names=["scene", "spp"])
    return pd.DataFrame({name: [table[s, n, name] for s, n in cases] for name in names}, index=index,
                        dtype=np.float64)


def _percent(wins: int, n: int) -> float | None:
    return 100.0 * wins / n if n else None


def _mean(values) -> float | None:
    values = list(values)
    return float(np.mean(values)) if values else None


def beats_cases(metrics: pd.DataFrame, comparisons: dict[str, dict], *, variants: tuple[str, ...],
                metric: str = "relmse", source: str = "metrics") -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """Test cases of Table 1 (``variants=("sbf", "nfor")``) or 2 (``("post",)``): a frame with
    columns ensemble, size, scene, spp, win (the ensemble's ``metric`` strictly below every
    variant's), and ``{ensemble: missing variants}`` of the full ensembles left out."""
    complete = {e: c for e, c in comparisons.items() if all(v in c["one_hot"] for v in variants)}
    excluded = {e: [v for v in variants if v not in c["one_hot"]] for e, c in comparisons.items() if e not in complete}
    names = sorted({e for e in complete} | {c["one_hot"][v] for c in complete.values() for v in variants})
    rows = []
    if names:
        values = metric_values(metrics, metric, names, source=source)
        for ensemble, found in complete.items():
            rivals = values[[found["one_hot"][v] for v in variants]].min(axis=1)
            for (scene, spp), own, rival in zip(values.index, values[ensemble], rivals):
                rows.append({"ensemble": ensemble, "size": found["size"], "scene": scene, "spp": spp,
                             "win": bool(own < rival)})
    return pd.DataFrame(rows, columns=["ensemble", "size", "scene", "spp", "win"]), excluded


def beats_table(cases: pd.DataFrame, *, sizes: list[int], spps: list[int]) -> pd.DataFrame:
    """Long table (size, spp, cases, wins, percent) with every size x spp, an ``Avg.`` spp per
    size and an ``Avg.`` size per spp (pooled over cases); ``percent`` is None when n = 0."""
    rows = []
    for size in [*sizes, "Avg."]:
        for spp in [*spps, "Avg."]:
            chosen = cases[((cases["size"] == size) if size != "Avg." else cases["size"].isin(sizes))
                           & ((cases["spp"] == spp) if spp != "Avg." else cases["spp"].isin(spps))]
            n, wins = len(chosen), int(chosen["win"].sum())
            rows.append({"size": str(size), "spp": str(spp), "cases": n, "wins": wins, "percent": _percent(wins, n)})
    return pd.DataFrame(rows, columns=["size", "spp", "cases", "wins", "percent"])


def _cell(value: float | None, digits: int = 1, unit: str = "") -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}{unit}"


def beats_markdown(table: pd.DataFrame, excluded: dict[str, list[str]], *, number: int, metric: str,
                   labels: dict[str, str], metric_label: str | None = None) -> str:
    """Table ``number`` (1 or 2) as Markdown: percent (n) per size and spp, the paper's Avg. row
    beside ours (relMSE, the paper's metric), and the full ensembles left out; the metric named
    by ``metric_label`` (its declared label; default its name)."""
    rivals = " and ".join(TABLE_VARIANTS[number])
    shown_metric = metric_label or metric
    spps = list(dict.fromkeys(table["spp"]))
    sizes = list(dict.fromkeys(table["size"]))
    lookup = table.set_index(["size", "spp"])
    lines = [f"# Table {number} ({shown_metric}): the ensemble against one-hot selection ({rivals})", "",
             f"Percentage of test cases (scene x spp x full ensemble of that size with the one-hot "
             f"variant(s) {rivals}) in which the ensemble's {shown_metric} is lower than every variant's; n "
             f"(cases) in parentheses; `Avg.` pools the cases of the row or column. Zheng et al. 2021 "
             f"Table {number} (relMSE only)." + ("" if metric == "relmse" else
                                                 f" **Extra: {shown_metric} is not a metric of the paper's table.**"),
             "", "| #Base | " + " | ".join(spps) + " |", "|---" * (len(spps) + 1) + "|"]
    for size in sizes:
        cells = [f"{_cell(lookup.loc[(size, s), 'percent'], unit=' %')} ({lookup.loc[(size, s), 'cases']})"
                 for s in spps]
        lines.append(f"| {size} | " + " | ".join(cells) + " |")
    if metric == "relmse":
        paper = PAPER_AVG[number]
        shown = [s for s in spps if s == "Avg." or int(s) in paper]
        ours = [_cell(lookup.loc[("Avg.", s), "percent"], unit=" %") for s in shown]
        in_range = table[(table["size"] != "Avg.") & (table["spp"] != "Avg.")
                         & table["spp"].isin([str(s) for s in paper if s != "Avg."])]
        overall = _percent(int(in_range["wins"].sum()), int(in_range["cases"].sum()))
        lines += ["", f"Beside the paper's Table {number} (Avg. row; our `Avg.` pools all our spp):", "",
                  "| | " + " | ".join(shown) + " |", "|---" * (len(shown) + 1) + "|",
                  "| Zheng et al. | " + " | ".join(_cell(paper.get(s if s == "Avg." else int(s)), unit=" %")
                                                  for s in shown) + " |",
                  "| ours | " + " | ".join(ours) + " |", "",
                  f"Our overall average over the paper's spp (4-256 present here): {_cell(overall, unit=' %')}."]
    if excluded:
        listed = "; ".join(f"{labels.get(e, e)} (no one-hot {', '.join(m)})" for e, m in excluded.items())
        lines += ["", f"Not in this table (variant set incomplete): {listed}."]
    if not sizes[:-1]:
        lines += ["", "No full ensemble in this config."]
    return "\n".join(lines) + "\n"


def ablation_cases(metrics: pd.DataFrame, timings: pd.DataFrame | None, comparisons: dict[str, dict], *,
                   metrics_source: str = "metrics", timings_source: str = "timings") -> pd.DataFrame:
    """One row per kind x full ensemble x case: kind, ensemble, ablation, scene, spp,
    relmse_ablation, relmse_full, dssim_* (NaN columns when the metrics have no DSSIM at all),
    seconds_ablation, seconds_full (NaN without ``timings``)."""
    pairs = [(kind, e, a) for e, c in comparisons.items() for kind, a in c["ablations"].items()]
    names = sorted({n for _, e, a in pairs for n in (e, a)})
    columns = ["kind", "ensemble", "ablation", "scene", "spp"] + [f"{q}_{w}" for q in ("relmse", "dssim", "seconds")
                                                                 for w in ("ablation", "full")]
    if not pairs:
        return pd.DataFrame(columns=columns)
    cases = _cases(metrics)
    tables = {"relmse": metric_values(metrics, "relmse", names, source=metrics_source)}
    if (metrics["metric"] == "dssim").any():
        tables["dssim"] = metric_values(metrics, "dssim", names, source=metrics_source)
    if timings is not None:
        tables["seconds"] = metric_values(timings, None, names, cases=cases, name_column="method",
                                          value_column="seconds", source=timings_source)
    rows = []
    for kind, ensemble, ablation in pairs:
        for i, (scene, spp) in enumerate(cases):
            row = {"kind": kind, "ensemble": ensemble, "ablation": ablation, "scene": scene, "spp": spp}
            for quantity in ("relmse", "dssim", "seconds"):
                got = tables.get(quantity)
                row[f"{quantity}_ablation"] = got[ablation].iloc[i] if got is not None else np.nan
                row[f"{quantity}_full"] = got[ensemble].iloc[i] if got is not None else np.nan
            rows.append(row)
    return pd.DataFrame(rows, columns=columns)


def _reproduced(rule: str | None, row: dict) -> str:
    if rule is None:
        return "n/a"
    if not row["cases"]:
        return "–"
    if rule == WORSE:
        return "yes" if row["loses"] >= 0.5 and row["relmse_ablation"] > row["relmse_full"] else "no"
    close = abs(row["relmse_ablation"] - row["relmse_full"]) <= 0.05 * row["relmse_full"]
    return "yes" if close and row["time_ratio"] is not None and row["time_ratio"] >= 5.0 else "no"


def ablation_table(cases: pd.DataFrame, *, spps: list[int]) -> pd.DataFrame:
    """Per kind (the order of :data:`SECTIONS`) x spp (and ``Avg.``, pooled): cases, the means of
    relMSE and DSSIM of the ablation and of its full ensemble, the fraction of cases the ablation
    loses (relMSE higher), the mean time ratio ablation/full (cases with a positive full time),
    the paper's claim and ``reproduced`` by the kind's rule (:data:`RULES`). None where n = 0."""
    rows = []
    for kind in [k for k in SECTIONS if k in set(cases["kind"])]:
        claim, rule = CLAIMS[kind]
        of_kind = cases[cases["kind"] == kind]
        for spp in [*spps, "Avg."]:
            chosen = of_kind if spp == "Avg." else of_kind[of_kind["spp"] == spp]
            timed = chosen[chosen["seconds_full"] > 0]
            row = {"kind": kind, "section": SECTIONS[kind], "spp": str(spp), "cases": len(chosen)}
            for column in ("relmse_ablation", "relmse_full", "dssim_ablation", "dssim_full"):
                row[column] = _mean(chosen[column].dropna())
            row["loses"] = _mean(chosen["relmse_ablation"] > chosen["relmse_full"])
            row["time_ratio"] = _mean(timed["seconds_ablation"] / timed["seconds_full"])
            row["claim"], row["reproduced"] = claim, _reproduced(rule, row)
            rows.append(row)
    return pd.DataFrame(rows, columns=["kind", "section", "spp", "cases", "relmse_ablation", "relmse_full",
                                       "dssim_ablation", "dssim_full", "loses", "time_ratio", "claim", "reproduced"])


def ablation_markdown(table: pd.DataFrame, cases: pd.DataFrame, *, labels: dict[str, str]) -> str:
    """The ablation table as Markdown, with the pairs it compares and the rules of ``reproduced``."""
    header = ["ablation", "spp", "n", "relMSE abl.", "relMSE full", "DSSIM abl.", "DSSIM full", "loses",
              "time abl./full", "paper's claim", "reproduced?"]
    lines = ["# Ablations of the ensemble (Zheng et al. 2021 Sec. 5.2.1-5.2.5)", "",
             "Each ablation against its full ensemble (same inputs, default weights, channels, solver and "
             "filter) over the scenes and ensembles that have it: mean relMSE and DSSIM of both, the "
             "fraction of cases in which the ablation's relMSE is higher (`loses`), the mean ratio of the "
             "combiners' own compute times (inputs excluded, from timings.csv). `Avg.` pools all cases (its "
             "mean errors weigh the low spp most).", "",
             "| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for row in table.to_dict("records"):
        name = f"{row['kind']} ({row['section']})" if row["section"] else row["kind"]
        cells = [name, row["spp"], str(row["cases"])] + [_cell(row[c], 4) for c in ("relmse_ablation", "relmse_full",
                                                                                     "dssim_ablation", "dssim_full")]
        cells += [_cell(None if row["loses"] is None else 100 * row["loses"], 0, " %"),
                  _cell(row["time_ratio"], 1, "x"), row["claim"] if row["spp"] == "Avg." else "",
                  row["reproduced"]]
        lines.append("| " + " | ".join(cells) + " |")
    if table.empty:
        lines.append("| (no ablation in this config) |" + " |" * (len(header) - 1))
    pairs = cases[["kind", "ensemble", "ablation"]].drop_duplicates()
    lines += ["", "Rules of `reproduced?`: " + "; ".join(f"{rule or 'n/a'}: {text}" for rule, text in RULES.items()
                                                       if rule is not None) + ".", "", "Pairs:"]
    lines += [f"- {k}: {labels.get(a, a)} vs {labels.get(e, e)}" for k, e, a in pairs.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def comparison_ranking(metrics: pd.DataFrame, methods: dict[str, dict], metric: str, *, noisy: str | None = "noisy",
                       source: str = "metrics") -> pd.DataFrame:
    """Score-and-rank table (:func:`mcbench.analysis.ranking.ranking_table`) of every comparison method
    (:func:`comparison_role` not None), the full ensembles of their input sets and the noisy
    input, with columns role and compared_with (the full ensembles of the same input set) first.
    Empty (no rows) when the config has no comparison method."""
    roles = {name: comparison_role(spec) for name, spec in methods.items()}
    comparisons = find_comparisons(methods)
    of_set = {name: [e for e, c in comparisons.items() if c["inputs"] == frozenset(methods[name].get("inputs", []))]
              for name, role in roles.items() if role is not None}
    if not of_set:
        return pd.DataFrame(columns=["role", "compared_with"])
    names = [n for n in methods if n in of_set or any(n in group for group in of_set.values())]
    names += [noisy] if noisy is not None and noisy in set(metrics["entry"]) else []
    metric_values(metrics, metric, names, source=source)
    table = ranking_table(metrics[metrics["entry"].isin(names)], metric)
    table.insert(0, "compared_with", [" ".join(of_set.get(n, [])) for n in table.index])
    table.insert(0, "role", [roles.get(n) or ("full ensemble" if n in comparisons else n) for n in table.index])
    return table


def write_onehot_tables(metrics_csv: str, metric: str, *, methods: dict[str, dict], labels: dict[str, str],
                        table1_csv: str, table1_md: str, table2_csv: str, table2_md: str,
                        metric_label: str | None = None) -> dict[int, pd.DataFrame]:
    """Tables 1 and 2 for ``metric`` (named ``metric_label`` in the Markdown) from ``metrics.csv``,
    each as CSV (long: size, spp, cases, wins, percent) and Markdown, written atomically."""
    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    comparisons = find_comparisons(methods)
    spps = sorted({int(s) for s in metrics["spp"]})
    sizes = sorted({c["size"] for c in comparisons.values()})
    out = {}
    for number, csv_path, md_path in ((1, table1_csv, table1_md), (2, table2_csv, table2_md)):
        cases, excluded = beats_cases(metrics, comparisons, variants=TABLE_VARIANTS[number], metric=metric,
                                      source=metrics_csv)
        table = beats_table(cases, sizes=sizes, spps=spps)
        write_csv(csv_path, table, float_format="%.4f")
        write_text(md_path, beats_markdown(table, excluded, number=number, metric=metric, labels=labels,
                                           metric_label=metric_label))
        out[number] = table
    return out


def write_ablation_table(metrics_csv: str, timings_csv: str, *, methods: dict[str, dict], labels: dict[str, str],
                         csv_path: str, md_path: str) -> pd.DataFrame:
    """The ablation table from ``metrics.csv`` and ``timings.csv``, as CSV and Markdown."""
    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    timings = read_table(timings_csv, columns=("scene", "spp", "method", "seconds"))
    cases = ablation_cases(metrics, timings, find_comparisons(methods), metrics_source=metrics_csv,
                           timings_source=timings_csv)
    table = ablation_table(cases, spps=sorted({int(s) for s in metrics["spp"]}))
    write_csv(csv_path, table, float_format="%.6g")
    write_text(md_path, ablation_markdown(table, cases, labels=labels))
    return table


def write_comparison_ranking(metrics_csv: str, metric: str, *, methods: dict[str, dict], labels: dict[str, str],
                             csv_path: str, md_path: str, metric_label: str | None = None) -> pd.DataFrame:
    """The comparison methods' score-and-rank table for ``metric`` (named ``metric_label`` in the
    Markdown), as CSV and Markdown."""
    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    table = comparison_ranking(metrics, methods, metric, source=metrics_csv)
    write_csv(csv_path, table.reset_index(), float_format="%.4f")
    text = (f"# Comparison ranking by {metric_label or metric}\n\nOne-hot variants, naive averages "
            f"and ablations ranked beside the full ensembles they belong to (and the noisy input), scored "
            f"as the main ranking tables (Zheng et al. 2021 Sec. 5.3.3; higher is better), kept out of the "
            f"main ranking pool.\n\n")
    if table.empty:
        text += "No comparison method in this config.\n"
    else:
        shown = {n: f"{labels.get(n, n)} [{role}]" for n, role in table["role"].items()}
        text += format_markdown(table.drop(columns=["role", "compared_with"]), shown) + "\n"
    write_text(md_path, text)
    return table
