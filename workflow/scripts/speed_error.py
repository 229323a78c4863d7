from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.figures import write_speed_error  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402

# rule speed_error of workflow/rules/figures.smk
run_logged(snakemake.log[0], write_speed_error, snakemake.input.metrics, snakemake.input.timings,
           snakemake.output[0], metric=snakemake.params.metric, labels=dict(snakemake.params.labels),
           inputs={name: list(names) for name, names in dict(snakemake.params.inputs).items()})
