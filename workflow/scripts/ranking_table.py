from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.report import write_extras_rankings, write_rankings

if snakemake.rule == "extras_table":
    run_logged(snakemake.log[0], write_extras_rankings, snakemake.input[0], snakemake.wildcards.metric,
               snakemake.output.csv, snakemake.output.md, pool=list(snakemake.params.pool),
               extras=list(snakemake.params.extras), labels=dict(snakemake.params.labels),
               tex_path=snakemake.output.tex)
else:
    run_logged(snakemake.log[0], write_rankings, snakemake.input[0], snakemake.wildcards.metric,
               snakemake.output.csv, snakemake.output.md, candidates=list(snakemake.params.candidates),
               labels=dict(snakemake.params.labels), tex_path=snakemake.output.tex,
               order=snakemake.params.order, note=snakemake.params.note)
