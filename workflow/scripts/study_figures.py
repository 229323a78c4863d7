from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.pool_study import write_study_figures_of  # noqa: E402

# rule study_figures of workflow/rules/study.smk
paths = {key: str(value) for key, value in snakemake.output.items()}
run_logged(snakemake.log[0], write_study_figures_of, snakemake.input.metrics, snakemake.input.timings,
           snakemake.input.recommendations, snakemake.input.scores_ci, list(snakemake.input.renders), paths,
           metric=snakemake.wildcards.metric, entries=list(snakemake.params.entries),
           labels=dict(snakemake.params.labels),
           inputs={name: list(names) for name, names in dict(snakemake.params.inputs).items()})
