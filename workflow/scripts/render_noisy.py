from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.render import render_noisy

run_logged(snakemake.log[0], render_noisy, snakemake.wildcards.scene, int(snakemake.wildcards.spp),
           snakemake.output[0], resolution=snakemake.params.resolution,
           variant=snakemake.params.variant, seed=snakemake.params.seed, threads=snakemake.threads)
