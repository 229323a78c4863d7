from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.oracle import run_oracle_study  # noqa: E402

params = snakemake.params
run_logged(snakemake.log[0], run_oracle_study, snakemake.wildcards.scene, snakemake.input.reference,
           table_csv=snakemake.output.table, table_md=snakemake.output.markdown,
           weights_png=snakemake.output.weights, denoisers=list(params.denoisers),
           repetitions=int(params.repetitions), spp=int(params.spp), downscale=int(params.downscale),
           resolution=params.resolution, variant=params.variant, features=params.get("features", "first_hit"), seed=int(params.seed),
           weights_dir=params.weights_dir, threads=snakemake.threads)
