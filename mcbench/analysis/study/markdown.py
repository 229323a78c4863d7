"""The study's tables as Markdown and as sentences a user can act on: one function per table of
:mod:`mcbench.analysis.study` and :func:`summary_markdown` over all of them. Pure text: the
numbers come from the tables; writing the files is :mod:`mcbench.analysis.study.writers`'."""

from __future__ import annotations

import pandas as pd

from mcbench.analysis import pool
from mcbench.analysis.study.data import BAND_TEXT, PAPER_ENTRIES, Resampling, finite_or_none, is_pool_name
from mcbench.analysis.study.findings import CLAIMS
from mcbench.analysis.study.pair_members import ALMOST, ALMOST_ALWAYS
from mcbench.analysis.study.paper import PAPER_TABLE3_BASES, paper_comparison, paper_kendall
from mcbench.analysis.study.recommendations import COMBINED_RULE
from mcbench.analysis.study.study_tables import StudyTables

__all__ = ["NO_RELMSE_MARKDOWN", "paper_comparison_markdown", "recommendation_sentences", "recommendations_markdown",
           "recommendations_both_sentences", "recommendations_both_markdown", "pair_members_markdown",
           "findings_markdown", "reference_noise_markdown", "summary_markdown", "PROVENANCE_HEADING",
           "provenance_markdown"]

# paper_table3.md when the study has no relMSE values
NO_RELMSE_MARKDOWN = ("# Beside the paper's Table 3 (relMSE scores)\n\nNo relMSE values in the metrics table "
                      "(or relmse not among the study's metrics).\n")


def _clean(record: dict) -> dict:
    """A table row with missing cells (None, NaN, pandas NA: what a concat or a CSV makes of an
    empty cell) as None."""
    return {k: (None if v is None or (not isinstance(v, str) and pd.isna(v)) else v) for k, v in record.items()}


def _cell(value, digits: int = 1, unit: str = "") -> str:
    number = finite_or_none(value)
    return "–" if number is None else f"{number:.{digits}f}{unit}"


def _ci_text(low, high, digits: int = 1) -> str:
    if finite_or_none(low) is None or finite_or_none(high) is None:
        return "no CI"
    return f"[{low:.{digits}f}, {high:.{digits}f}]"

def _metric_label(metric, metric_labels: dict[str, str] | None) -> str:
    """How a metric is named in the text: its label in ``metric_labels`` (the metrics'
    declarations, ``metrics/<name>.py``), else its name."""
    return (metric_labels or {}).get(metric, metric)


def _label(name, labels: dict[str, str]) -> str:
    if name is None:
        return "–"
    return labels.get(name) or (pool.candidate(name).label if is_pool_name(name) else str(name))


def _percent(fraction) -> str:
    number = finite_or_none(fraction)
    return "–" if number is None else f"{100.0 * number:.0f} %"


def _score_ci(score, low, high) -> str:
    """A score with its interval; "–" alone when there is no score."""
    return "–" if finite_or_none(score) is None else f"{_cell(score)} {_ci_text(low, high)}"


def _of(name, count, labels: dict[str, str]) -> str:
    """A pick's label with the number of candidates it was picked from."""
    return "–" if name is None else f"{_label(name, labels)} (of {count})"


def _scope_text(scope: str, key: str) -> str:
    if scope == "size":
        return f"size {key}"
    if scope == "band":
        return f"{key} ({BAND_TEXT.get(key, '')})"
    return f"overall {key}" + (f" (size < {pool.FEWER_THAN})" if key == "fewer" else "")


def paper_comparison_markdown(ranking: pd.DataFrame, *, names: dict[int, str] | None = None,
                              labels: dict[str, str] | None = None, entries: int | None = None) -> str:
    """Markdown: per Table 3 candidate and spp ``ours (paper)``, the Avg. differences and the
    Kendall taus; a note when our ranking does not have the paper's 40 entries (``entries``,
    default ``len(ranking)``)."""
    labels = labels or {}
    table = paper_comparison(ranking, names=names)
    kendall = paper_kendall(ranking, names=names)
    entries = len(ranking) if entries is None else int(entries)
    spps = list(dict.fromkeys(table["spp"]))
    lines = ["# Beside the paper's Table 3 (relMSE scores)", "",
             "Our relMSE ranking scores (mean over our scenes) of the candidates of Zheng et al. 2021 Table 3 "
             "and, in parentheses, the paper's (mean over its 30 scenes); – where one side has no value. "
             "`Avg. (common spp)` averages both over the spp both tables have.", ""]
    if entries != PAPER_ENTRIES:
        lines += [f"**Scale:** our ranking has {entries} entries, the paper's {PAPER_ENTRIES}: the scores are not on "
                  f"the same scale (the best of K entries scores K), so compare orders, not numbers.", ""]
    else:
        lines += [f"Both rankings have {PAPER_ENTRIES} entries (same scale).", ""]
    lines += ["| candidate | " + " | ".join(spps) + " | Avg. diff |", "|---" * (len(spps) + 2) + "|"]
    for cid, group in table.groupby("id", sort=False):
        name = group["candidate"].iloc[0]
        cells = [f"{_cell(r.ours)} ({_cell(r.paper)})" for r in group.itertuples()]
        diff = group.loc[group["spp"] == "Avg.", "difference"].iloc[0]
        label = labels.get(name, pool.candidate(cid).label if name == pool.candidate_name(cid) else name)
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {_cell(diff)} |")
    missing = sorted({r.note for r in table.itertuples() if r.note.endswith("not in our ranking")})
    lines += [""] + [f"- {m}" for m in missing]
    lines += ["", "Kendall tau-b of our ordering of these candidates against the paper's:", ""]
    bases = paper_kendall(ranking, names=names, ids=PAPER_TABLE3_BASES)
    bases_prefix = f"among its bases alone (IDs {', '.join(map(str, PAPER_TABLE3_BASES))}), "
    for prefix, rows in (("", kendall), (bases_prefix, bases)):
        for r in rows.itertuples():
            text = "undefined (fewer than two candidates, or a constant side)" if r.tau is None else \
                f"tau = {r.tau:.3f} (p = {r.p_value:.3g}, n = {r.n})"
            lines.append(f"- {prefix}by {r.basis}: {text}")
    return "\n".join(lines) + "\n"

def recommendation_sentences(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                             n_resamples: int | None = None, metric_labels: dict[str, str] | None = None) -> list[str]:
    """One sentence a user can act on per row of :func:`~mcbench.analysis.study.recommendations.recommendations`
    (each metric named by its label in ``metric_labels``)."""
    labels = labels or {}
    out = []
    for r in map(_clean, table.to_dict("records")):
        r["paper_id"] = None if r["paper_id"] is None else int(r["paper_id"])
        metric = _metric_label(r["metric"], metric_labels)
        if r["scope"] == "size":
            lead = f"With {r['key']} base denoisers ({metric})"
        elif r["scope"] == "band":
            lead = f"For {BAND_TEXT.get(r['key'], r['key'])} ({metric}; our spp {r['spp'] or 'none'})"
        elif r["key"] == "fewer":
            lead = f"Overall with fewer than {pool.FEWER_THAN} base denoisers ({metric})"
        else:
            lead = f"Overall ({metric}), {'first' if r['key'] == 'best' else 'second'} choice"
        if r["ours"] is None:
            out.append(f"{lead}: no recommendation ({r['note']}).")
            continue
        resamples = f" of {n_resamples}" if n_resamples else ""
        what = "top" if r["key"] != "second" else "second"
        sentence = (f"{lead}: use {_label(r['ours'], labels)} (score {_cell(r['ours_score'])} "
                    f"{_ci_text(r['ours_ci_low'], r['ours_ci_high'])}, {what} in {_percent(r['ours_fraction'])}"
                    f"{resamples} scene resamples)")
        if r.get("named") is not None and r["named"] != r["ours"]:
            sentence += (f"; among only the paper's named ensembles: {_label(r['named'], labels)} "
                         f"(score {_cell(r['named_score'])})")
        elif r.get("named") is not None:
            sentence += "; also the best of the paper's named ensembles"
        if r["paper"] is None:
            sentence += "; the paper recommends none for this case."
        elif r["paper"] == r["ours"]:
            sentence += f"; the paper recommends the same, #{r['paper_id']}."
        elif r["paper_score"] is None:
            sentence += f"; the paper recommends #{r['paper_id']}, which is not in our data."
        else:
            verdict = {"yes": "really different from ours", "no": "not really different from ours",
                       "": "difference undetermined"}[r["real_difference"] or ""]
            sentence += (f"; the paper recommends #{r['paper_id']} ({what} in {_percent(r['paper_fraction'])}), "
                         f"{verdict} (ours - paper's {_cell(r['difference'])}, "
                         f"{_ci_text(r['difference_ci_low'], r['difference_ci_high'])}).")
        notes = [n for n in (r["note"] or "").split("; ") if n and not n.startswith("the paper's")]
        if notes:
            sentence = sentence[:-1] + f" ({'; '.join(notes)})."
        out.append(sentence)
    return out


def recommendations_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                             resampling: Resampling = Resampling(), metric_labels: dict[str, str] | None = None) -> str:
    """The recommendations as a short Markdown table and the sentences (each metric named by its
    label in ``metric_labels``)."""
    labels = labels or {}
    level = f"{100 * resampling.confidence:.0f} %"
    lines = ["# Recommendations derived from the data (Zheng et al. 2021 Sec. 5.3.5-5.3.6)", "",
             f"Best pool ensemble per scope by mean ranking score (bases never compete), its {level} scene-bootstrap "
             f"interval and the fraction of {resampling.n_resamples} paired scene resamples in which it holds the "
             f"place (seed {resampling.seed}); beside it the best among only the ensembles the paper names "
             f"({', '.join(f'#{i}' for i in pool.PAPER_NAMED_IDS)}; the other pool rows are ours), then the "
             f"paper's choice. A difference is real when the paired interval of ours - paper's excludes 0. "
             f"'overall fewer': the best with fewer than {pool.FEWER_THAN} members (Sec. 5.3.6: #20 for users "
             f"who want fewer base denoisers than #27). Both metrics together: recommendations_metrics.md.", "",
             "| metric | scope | ours (all pool ensembles) | score | resamples | ours (paper-named only) | score | paper | "
             "score | resamples | ours - paper | real? |",
             "|---" * 12 + "|"]
    for r in map(_clean, table.to_dict("records")):
        lines.append(f"| {_metric_label(r['metric'], metric_labels)} | {_scope_text(r['scope'], r['key'])} | "
                     f"{_of(r['ours'], r['candidates'], labels)} | "
                     f"{_score_ci(r['ours_score'], r['ours_ci_low'], r['ours_ci_high'])} | "
                     f"{_percent(r['ours_fraction'])} | {_of(r.get('named'), r.get('named_candidates'), labels)} | "
                     f"{_cell(r.get('named_score'))} | {_label(r['paper'], labels)} | {_cell(r['paper_score'])} | "
                     f"{_percent(r['paper_fraction'])} | {_cell(r['difference'])} "
                     f"{'' if r['difference'] is None else _ci_text(r['difference_ci_low'], r['difference_ci_high'])}"
                     f" | {r['real_difference'] or '–'} |")
    lines += ["", *[f"- {s}" for s in recommendation_sentences(table, labels=labels, n_resamples=resampling.n_resamples,
                                                                metric_labels=metric_labels)]]
    return "\n".join(lines) + "\n"


def recommendations_both_sentences(table: pd.DataFrame, *, labels: dict[str, str] | None = None) -> list[str]:
    """One line per scope of :func:`~mcbench.analysis.study.recommendations.recommendations_both` (both sets)."""
    labels = labels or {}
    out = []
    for (scope, key), group in table.groupby(["scope", "key"], sort=False):
        parts = []
        for r in map(_clean, group.to_dict("records")):
            if r["combined"] is None:
                parts.append(f"{r['set']}: none ({r['note']})")
                continue
            parts.append(f"{r['set']}: relMSE {_label(r['relmse'], labels)}, DSSIM {_label(r['dssim'], labels)}, "
                         f"combined (ours) {_label(r['combined'], labels)} ({_cell(r['combined_score'])} "
                         f"{_ci_text(r['combined_ci_low'], r['combined_ci_high'])}, "
                         f"{_percent(r['combined_fraction'])} of resamples)")
        paper = group["paper_id"].iloc[0]
        tail = "" if pd.isna(paper) else f"; the paper: #{int(paper)}"
        out.append(f"{_scope_text(scope, key)}: " + "; ".join(parts) + tail + ".")
    return out


def recommendations_both_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                                  resampling: Resampling = Resampling()) -> str:
    """:func:`~mcbench.analysis.study.recommendations.recommendations_both` as Markdown: both metrics' picks
    side by side and our combined pick."""
    labels = labels or {}
    level = f"{100 * resampling.confidence:.0f} %"
    lines = ["# Recommendations by relMSE and DSSIM together (Zheng et al. 2021 Sec. 5.3.5-5.3.6)", "",
             "Sec. 5.3.6 recommends #27 as working well 'under both the relMSE and DSSIM metrics' without a "
             "formula for weighing the two. Here each metric's pick, side by side, and one combined rule, "
             f"**{COMBINED_RULE}**; its {level} scene-bootstrap interval and the fraction of "
             f"{resampling.n_resamples} paired scene resamples in which the pick holds the place. Sets: "
             f"'all' = every pool ensemble in our data; 'paper-named' = only the ensembles the paper names "
             f"({', '.join(f'#{i}' for i in pool.PAPER_NAMED_IDS)}).", ""]
    if table.empty:
        return "\n".join(lines + ["Needs both relmse and dssim among the study's metrics, with values in "
                                  "metrics.csv; one is missing."]) + "\n"
    lines += ["| scope | set (candidates) | relMSE pick | score | DSSIM pick | score | combined pick (ours) | score | resamples "
              "| paper | paper's combined score | agrees |", "|---" * 12 + "|"]
    for r in map(_clean, table.to_dict("records")):
        lines.append(f"| {_scope_text(r['scope'], r['key'])} | {r['set']} ({r['candidates']}) | "
                     f"{_label(r['relmse'], labels)} | "
                     f"{_cell(r['relmse_score'])} | {_label(r['dssim'], labels)} | {_cell(r['dssim_score'])} | "
                     f"{_label(r['combined'], labels)} | "
                     f"{_score_ci(r['combined_score'], r['combined_ci_low'], r['combined_ci_high'])} | "
                     f"{_percent(r['combined_fraction'])} | "
                     f"{_label(r['paper'], labels)} | {_cell(r['paper_combined_score'])} | {r['agrees'] or '–'} |")
    lines += ["", *[f"- {s}" for s in recommendations_both_sentences(table, labels=labels)]]
    return "\n".join(lines) + "\n"

def pair_members_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                          resampling: Resampling = Resampling(), skipped: dict[str, str] | None = None,
                          metric_labels: dict[str, str] | None = None) -> str:
    """:func:`~mcbench.analysis.study.pair_members.pair_members` as Markdown: per metric (named by its
    label in ``metric_labels``), wins/cases per spp and overall with the interval and verdict, then
    the cases each pair fails."""
    labels = labels or {}
    lines = ["# Finding (b): size-2 ensembles against each of their members (Zheng et al. 2021 Sec. 5.3.4)", "",
             "The paper: \"a combination of 2 base denoisers almost always outperforms the corresponding individual "
             "base denoisers\". Per metric, every size-2 ensemble of the pool in our data against each of its two "
             "members and against both at once: cases in which its error is strictly below the member's "
             "(wins/cases) per spp and over all spp. 'Almost always' is read as a fraction above "
             f"{ALMOST_ALWAYS:.2f} (worse in under {100 * ALMOST:.0f} % of cases): reproduced when the "
             f"{100 * resampling.confidence:.0f} % scene-bootstrap interval of the fraction lies above it, not "
             "reproduced when below, inconclusive otherwise.", ""]
    for metric, reason in (skipped or {}).items():
        lines += [f"- {_metric_label(metric, metric_labels)}: {reason}"]
    if table.empty:
        return "\n".join(lines + ["", "No size-2 ensemble of the pool with both members in our data."]) + "\n"
    for metric, by_metric in table.groupby("metric", sort=False):
        spps = [s for s in dict.fromkeys(by_metric["spp"]) if s != "all"]
        lines += ["", f"## {_metric_label(metric, metric_labels)}", "",
                  "| size-2 ensemble | outperforms | " + " | ".join(f"{s} spp" for s in spps)
                  + " | all spp | fraction | interval | verdict |", "|---" * (len(spps) + 6) + "|"]
        failed = []
        for (name, member), group in by_metric.groupby(["ensemble", "member"], sort=False):
            cells = {r["spp"]: r for r in map(_clean, group.to_dict("records"))}
            every = cells["all"]
            against = "both members" if member == "both" else _label(member, labels)
            lines.append(f"| {_label(name, labels)} | {against} | "
                         + " | ".join(f"{cells[s]['wins']}/{cells[s]['cases']}" for s in spps)
                         + f" | {every['wins']}/{every['cases']} | {_cell(every['fraction'], 3)} | "
                         f"{_ci_text(every['ci_low'], every['ci_high'], 3)} | **{every['verdict']}** |")
            if every["failures"]:
                failed.append(f"- {_label(name, labels)} does not outperform {against} in: "
                              + ", ".join(str(every["failures"]).split()))
        lines += ["", "Cases the pair does not outperform (`scene@spp`):", ""] + (failed or ["- none"])
    return "\n".join(lines) + "\n"


def findings_markdown(table: pd.DataFrame, *, resampling: Resampling = Resampling(),
                      metric_labels: dict[str, str] | None = None) -> str:
    """The findings as Markdown, one section per metric (named by its label in ``metric_labels``)
    and finding."""
    level = f"{100 * resampling.confidence:.0f} %"
    lines = ["# The paper's findings (Zheng et al. 2021 Sec. 5.3.4), checked with numbers", "",
             f"Means over scenes with {level} paired scene-bootstrap intervals ({resampling.n_resamples} resamples, "
             f"seed {resampling.seed}; BCa, percentile where BCa is degenerate). A claim 'above t' is reproduced "
             f"when its interval lies above t, not reproduced when below, inconclusive when it contains t.", ""]
    for metric, by_metric in table.groupby("metric", sort=False):
        lines += [f"## {_metric_label(metric, metric_labels)}", ""]
        for finding, group in by_metric.groupby("finding", sort=True):
            lines += [f"### {finding}. {CLAIMS[finding]}", "", "| quantity | estimate | interval | verdict | note |",
                      "|---|---|---|---|---|"]
            digits = 3 if finding == "b" or "fraction" in " ".join(group["quantity"]) else 2
            for r in map(_clean, group.to_dict("records")):
                verdict = f"**{r['verdict']}**" if r["verdict"] else ""
                interval = "" if r["ci_low"] is None and r["ci_high"] is None else _ci_text(r["ci_low"], r["ci_high"],
                                                                                            digits)
                lines.append(f"| {r['quantity']} | {_cell(r['estimate'], digits)} | {interval} | {verdict} | "
                             f"{r['note']} |")
            rules = list(dict.fromkeys(r for r in group["rule"] if r))
            lines += [""] + [f"Rule: {r}." for r in rules] + [""]
    return "\n".join(lines)


def reference_noise_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                             resampling: Resampling = Resampling()) -> str:
    """The reference-noise table as Markdown with a verdict sentence."""
    labels = labels or {}
    lines = ["# References you can trust: raw against corrected relMSE", "",
             "Scores by relMSE against the reference (raw) and by relMSE corrected for the reference's own "
             "noise with its stored variance (corrected; `mcbench.analysis.metrics.relmse_corrected`). An entry's score "
             "changes *really* when the paired scene-bootstrap interval of its score change excludes 0 "
             f"({100 * resampling.confidence:.0f} %, {resampling.n_resamples} resamples).", ""]
    if table.empty:
        return "\n".join(lines + ["No relmse and relmse_corrected values to compare (both must be configured)."]) + "\n"
    lines += ["| spp | Kendall τ | largest change | real changes | top 3 raw | top 3 corrected |", "|---|---|---|---|---|---|"]
    for r in map(_clean, table.to_dict("records")):
        tops = [", ".join(labels.get(n, n) for n in str(r[k] or "").split()) for k in ("top_raw", "top_corrected")]
        changed = ", ".join(labels.get(n, n) for n in str(r["changed"] or "").split()) or "none"
        lines.append(f"| {r['spp']} | {_cell(r['kendall_tau'], 3)} | {_cell(r['max_abs_change'], 2)} | "
                     f"{r['real_changes']} ({changed}) | {tops[0]} | {tops[1]} |")
    disagree = [str(s) for s, a in zip(table["spp"], table["agree"]) if a != "yes"]
    lines += ["", "Verdict: " + ("the raw and corrected rankings agree within the intervals at every spp; the "
                                 "references are quiet enough for this study." if not disagree else
                                 "the reference noise really changes scores at spp " + ", ".join(disagree)
                                 + "; there, read the corrected ranking (or render longer references).")]
    return "\n".join(lines) + "\n"


#: summary.md's provenance section. Its heading names the machine, so that
#: :func:`mcbench.analysis.run_comparison.table_without_timing` leaves the section out like the
#: other machine-dependent text: two runs of one study on two commits or machines compare equal.
PROVENANCE_HEADING = "## Provenance (commit, config, machine, versions)"

# the versions the short block names, in this order (the manifest's keys -> the names shown)
_KEY_VERSIONS = {"mcbench": "mcbench", "mitsuba": "Mitsuba", "drjit": "Dr.Jit", "oidn": "OIDN (pyoidn)",
                 "torch": "torch", "numpy": "NumPy", "flip_evaluator": "flip-evaluator",
                 "snakemake": "Snakemake", "python": "Python"}


def _yes_no(value) -> str:
    return {True: "yes", False: "no"}.get(value, str(value))


def provenance_markdown(manifest: dict) -> list[str]:
    """The short provenance block (Markdown list lines) of a run's manifest
    (:func:`mcbench.pipeline.provenance.collect_provenance`, read from ``results/manifest.json``):
    the commit and whether the tree was clean, the config digest, the CPU (model, vendor/family/
    model numbers, AVX2/AVX-512F, logical cores) and the key library versions. A missing field
    reads "unknown" (an older or partial manifest still renders)."""
    git, cpu, versions = (manifest.get(k) or {} for k in ("git", "cpu", "versions"))
    clean = git.get("clean", "unknown")
    tree = {True: "clean tree", False: "uncommitted changes"}.get(clean, f"tree state {clean}")
    shown = [f"{label} {versions[key]}" for key, label in _KEY_VERSIONS.items() if key in versions]
    return [f"- Commit: `{git.get('commit', 'unknown')}` ({tree})",
            f"- Config digest: `{manifest.get('config_digest', 'unknown')}`",
            f"- CPU: {cpu.get('model', 'unknown')} (vendor {cpu.get('vendor', 'unknown')}, family "
            f"{cpu.get('family', 'unknown')}, model {cpu.get('model_number', 'unknown')}); AVX2 "
            f"{_yes_no(cpu.get('avx2', 'unknown'))}, AVX-512F {_yes_no(cpu.get('avx512f', 'unknown'))}; "
            f"{cpu.get('logical_cores', 'unknown')} logical cores",
            f"- Versions: {', '.join(shown) if shown else 'unknown'}"]


def summary_markdown(tables: StudyTables, *, source: str, provenance: dict | None = None) -> str:
    """``summary.md``: per metric its grid, the metrics skipped (no values in ``source``, the
    metrics table's file name), the recommendation sentences of each metric and of both together,
    the Kendall taus beside the paper's Table 3, the reference-noise verdict and every finding's
    verdict with its estimate and interval; last, when ``provenance`` (the run's manifest) is
    given, its short block under :data:`PROVENANCE_HEADING` (:func:`provenance_markdown`)."""
    resampling, shown = tables.resampling, tables.labels
    lines = ["# The 39-candidate study: summary", "",
             f"Scene bootstrap: {resampling.n_resamples} paired resamples, seed {resampling.seed}, "
             f"{100 * resampling.confidence:.0f} % intervals. Rows of the pool marked 'filled' are our choice, "
             f"not the paper's (see mcbench/analysis/pool.py).", ""]
    for metric, data in tables.data.items():
        lines.append(f"- {_metric_label(metric, tables.metric_labels)}: {len(data.scenes)} scene(s), spp "
                     f"{', '.join(map(str, data.spps))}, {data.entries} entries"
                     + ("" if data.entries == PAPER_ENTRIES else f" (the paper: {PAPER_ENTRIES})"))
    lines += [f"- {m}: no values in {source}; skipped" for m in tables.skipped]
    lines += ["", "## Recommendations", ""]
    lines += [f"- {s}" for s in recommendation_sentences(tables.recommendations, labels=shown,
                                                          n_resamples=resampling.n_resamples,
                                                          metric_labels=tables.metric_labels)]
    both = tables.recommendations_metrics
    lines += ["", "## Recommendations by relMSE and DSSIM together", "", f"Combined rule: {COMBINED_RULE}.", ""]
    lines += [f"- {s}" for s in recommendations_both_sentences(both, labels=shown)] if len(both) else \
        ["- needs both relmse and dssim in the study's metrics"]
    if tables.paper_kendall is not None:
        lines += ["", "## Beside the paper's Table 3", ""]
        for r in tables.paper_kendall.itertuples():
            lines.append(f"- Kendall tau by {r.basis}: " + ("undefined" if r.tau is None else
                                                            f"{r.tau:.3f} (p = {r.p_value:.3g}, n = {r.n})"))
    noise_text = reference_noise_markdown(tables.reference_noise, labels=shown, resampling=resampling)
    lines += ["", "## References", "", noise_text.strip().splitlines()[-1]]
    lines += ["", "## Findings", ""]
    # finding (b)'s per-(pair, member) verdicts are its parts: pair_members.md and findings.md hold them
    find_table = tables.findings
    parts = (find_table["finding"] == "b") & find_table["quantity"].str.startswith("#")
    headline = (find_table["verdict"] != "") & ~parts
    for r in map(_clean, find_table[headline].to_dict("records")):
        numbers = "" if r["estimate"] is None else \
            f" ({_cell(r['estimate'], 3)}, {_ci_text(r['ci_low'], r['ci_high'], 3)})"
        lines.append(f"- {_metric_label(r['metric'], tables.metric_labels)}, {r['finding']}: {r['quantity']}: "
                     f"**{r['verdict']}**{numbers}")
    if provenance is not None:
        lines += ["", PROVENANCE_HEADING, "", *provenance_markdown(provenance)]
    return "\n".join(lines) + "\n"
