from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.rendering import merge_reference  # noqa: E402

run_logged(snakemake.log[0], merge_reference, list(snakemake.input), snakemake.output[0],
           scene=snakemake.wildcards.scene)
