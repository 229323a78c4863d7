from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.comparisons import write_onehot_tables  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402

# rule comparison_onehot of workflow/rules/comparisons.smk
output = snakemake.output
run_logged(snakemake.log[0], write_onehot_tables, snakemake.input.metrics, snakemake.wildcards.metric,
           table1_csv=output.table1_csv, table1_md=output.table1_md, table2_csv=output.table2_csv,
           table2_md=output.table2_md, methods=dict(snakemake.params.methods), labels=dict(snakemake.params.labels))
