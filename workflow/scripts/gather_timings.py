from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.metrics import gather_timings

run_logged(snakemake.log[0], gather_timings, list(snakemake.input), snakemake.output[0])
