from mcbench.logs import run_logged
from mcbench.steps import gather_tables

run_logged(snakemake.log[0], gather_tables, list(snakemake.input), snakemake.output[0])
