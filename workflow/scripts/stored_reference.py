from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.reference_sources import stored_reference  # noqa: E402

# rule stored_reference of workflow/rules/render.smk
run_logged(snakemake.log[0], stored_reference, snakemake.params.record, snakemake.output[0])  # noqa: F821
