from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.rendering import render_reference_chunk  # noqa: E402

run_logged(snakemake.log[0], render_reference_chunk, snakemake.wildcards.scene, snakemake.params.spp,
           int(snakemake.wildcards.chunk), snakemake.output[0], resolution=snakemake.params.resolution,
           variant=snakemake.params.variant, features=snakemake.params.get("features", "first_hit"), seed=snakemake.params.seed, threads=snakemake.threads)
