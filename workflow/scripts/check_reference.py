from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.reference_sources import check_stored_reference  # noqa: E402

# rule check_reference of workflow/rules/render.smk
run_logged(snakemake.log[0], check_stored_reference, snakemake.wildcards.scene,  # noqa: F821
           snakemake.input.reference, snakemake.input.render, snakemake.output[0])  # noqa: F821
