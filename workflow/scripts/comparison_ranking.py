from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.comparisons import write_comparison_ranking  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402

# rule comparison_ranking of workflow/rules/comparisons.smk
run_logged(snakemake.log[0], write_comparison_ranking, snakemake.input.metrics, snakemake.wildcards.metric,
           csv_path=snakemake.output.csv, md_path=snakemake.output.md, methods=dict(snakemake.params.methods),
           labels=dict(snakemake.params.labels))
