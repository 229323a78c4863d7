from mcbench.logs import run_logged
from mcbench.steps import write_rankings

run_logged(snakemake.log[0], write_rankings, snakemake.input[0], snakemake.wildcards.metric,
           snakemake.output.csv, snakemake.output.md, candidates=list(snakemake.params.candidates),
           labels=dict(snakemake.params.labels), tex_path=snakemake.output.tex)
