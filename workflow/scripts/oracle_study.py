import os

os.environ.setdefault("NUMBA_NUM_THREADS", str(snakemake.threads))
os.environ.setdefault("OMP_NUM_THREADS", str(snakemake.threads))
os.environ["MCBENCH_WEIGHTS_DIR"] = os.path.abspath(snakemake.params.weights_dir)

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.oracle import run_oracle_study  # noqa: E402

params = snakemake.params
run_logged(snakemake.log[0], run_oracle_study, snakemake.wildcards.scene, snakemake.input.reference,
           table_csv=snakemake.output.table, table_md=snakemake.output.markdown,
           weights_png=snakemake.output.weights, denoisers=list(params.denoisers),
           repetitions=int(params.repetitions), spp=int(params.spp), downscale=int(params.downscale),
           resolution=params.resolution, variant=params.variant, seed=int(params.seed),
           threads=snakemake.threads)
