from mcbench.logs import run_logged
from mcbench.steps import write_gallery

run_logged(snakemake.log[0], write_gallery, dict(snakemake.params.references), snakemake.output[0])
