from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.report import write_gallery

run_logged(snakemake.log[0], write_gallery, dict(snakemake.params.references), snakemake.output[0])
