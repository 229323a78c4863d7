"""The comparison tables of Zheng et al. 2021 Sec. 5.2 (rules in workflow/rules/comparisons.smk):
one script for the three rules, dispatched on the rule's name."""

from mcbench.pipeline.threads import limit_threads

if "snakemake" in globals():  # a test may run this file with a stand-in snakemake object
    limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.comparisons import write_ablation_table, write_comparison_ranking, write_onehot_tables  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402


def run(smk) -> None:
    """Run the step of rule ``smk.rule`` with the rule's input, output and params."""
    options = {"methods": dict(smk.params.methods), "labels": dict(smk.params.labels)}
    if smk.rule == "comparison_onehot":
        run_logged(smk.log[0], write_onehot_tables, smk.input.metrics, smk.wildcards.metric,
                   table1_csv=smk.output.table1_csv, table1_md=smk.output.table1_md,
                   table2_csv=smk.output.table2_csv, table2_md=smk.output.table2_md, **options)
    elif smk.rule == "comparison_ablations":
        run_logged(smk.log[0], write_ablation_table, smk.input.metrics, smk.input.timings,
                   csv_path=smk.output.csv, md_path=smk.output.md, **options)
    elif smk.rule == "comparison_ranking":
        run_logged(smk.log[0], write_comparison_ranking, smk.input.metrics, smk.wildcards.metric,
                   csv_path=smk.output.csv, md_path=smk.output.md, **options)
    else:
        raise ValueError(f"comparison_tables.py: no step for rule '{smk.rule}'")


if "snakemake" in globals():
    run(snakemake)  # noqa: F821
