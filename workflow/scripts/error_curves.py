from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.figures import write_error_curves  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402

# rule error_curves of workflow/rules/figures.smk
run_logged(snakemake.log[0], write_error_curves, snakemake.input.metrics, snakemake.wildcards.metric,
           snakemake.output[0], labels=dict(snakemake.params.labels), entries=list(snakemake.params.entries))
