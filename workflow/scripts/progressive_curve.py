from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.progressive_study import run_consistency_curve  # noqa: E402

# rule progressive_curve of workflow/rules/progressive_study.smk
params = snakemake.params
run_logged(snakemake.log[0], run_consistency_curve, snakemake.wildcards.scene, snakemake.input.reference,
           table_csv=snakemake.output.table, table_md=snakemake.output.markdown,
           figure_png=snakemake.output.figure, spp_levels=[int(s) for s in params.spp], base=params.base,
           divergence=params.divergence, downscale=int(params.downscale), resolution=params.resolution,
           variant=params.variant, features=params.get("features", "first_hit"), seed=int(params.seed),
           weights_dir=params.weights_dir, threads=snakemake.threads)
