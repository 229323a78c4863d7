from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.training import write_correlated_training_inputs

run_logged(snakemake.log[0], write_correlated_training_inputs, snakemake.wildcards.base, list(snakemake.input),
           list(snakemake.output), threads=snakemake.threads)
