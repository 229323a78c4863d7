from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.reference_sources import store_reference_chunks  # noqa: E402

# rule store_reference of workflow/rules/render.smk
run_logged(snakemake.log[0], store_reference_chunks, snakemake.wildcards.scene, list(snakemake.input),  # noqa: F821
           snakemake.output[0], features=snakemake.params.features)  # noqa: F821
