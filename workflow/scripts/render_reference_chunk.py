from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.render import render_reference_chunk

run_logged(snakemake.log[0], render_reference_chunk, snakemake.wildcards.scene, snakemake.params.spp,
           int(snakemake.wildcards.chunk), snakemake.output[0], resolution=snakemake.params.resolution,
           variant=snakemake.params.variant, seed=snakemake.params.seed, threads=snakemake.threads)
