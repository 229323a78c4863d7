from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.figures import write_error_curves, write_speed_error  # noqa: E402

# the two rules of workflow/rules/figures.smk
labels = dict(snakemake.params.labels)
if snakemake.rule == "speed_error":
    run_logged(snakemake.log[0], write_speed_error, snakemake.input.metrics, snakemake.input.timings,
               snakemake.output[0], metric=snakemake.params.metric, labels=labels,
               inputs={name: list(names) for name, names in dict(snakemake.params.inputs).items()})
else:
    run_logged(snakemake.log[0], write_error_curves, snakemake.input.metrics, snakemake.wildcards.metric,
               snakemake.output[0], labels=labels, entries=list(snakemake.params.entries))
