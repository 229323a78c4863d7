from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.render import merge_reference

run_logged(snakemake.log[0], merge_reference, list(snakemake.input), snakemake.output[0])
