from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.training import write_training_example

settings = snakemake.params.settings
run_logged(snakemake.log[0], write_training_example, int(snakemake.wildcards.seed), list(snakemake.output),
           spp_levels=settings["spp"], target_spp=settings["target_spp"], resolution=settings["resolution"],
           crop_size=settings["crop"], variant=snakemake.params.variant, threads=snakemake.threads)
