from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.rankings import write_rankings  # noqa: E402

# rule ranking_table of workflow/rules/rankings.smk
run_logged(snakemake.log[0], write_rankings, snakemake.input[0], snakemake.wildcards.metric,
           snakemake.output.csv, snakemake.output.md, entries=list(snakemake.params.entries),
           labels=dict(snakemake.params.labels), tex_path=snakemake.output.tex,
           order=snakemake.params.order, note=snakemake.params.note,
           scenes_csv=snakemake.input.scenes)
