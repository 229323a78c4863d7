from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.training import write_training_example  # noqa: E402

settings = snakemake.params.settings
run_logged(snakemake.log[0], write_training_example, int(snakemake.wildcards.seed), list(snakemake.output),
           spp_levels=settings["spp"], target_spp=settings["target_spp"], resolution=settings["resolution"],
           crop_size=settings["crop"], variant=snakemake.params.variant,
           features=snakemake.params.get("features", "first_hit"), threads=snakemake.threads)
