from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from pathlib import Path  # noqa: E402

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.pool_study import write_study, write_study_figures_of  # noqa: E402

# the two rules of workflow/rules/study.smk
if snakemake.rule == "study_tables":
    run_logged(snakemake.log[0], write_study, snakemake.input.metrics, str(Path(snakemake.output.summary).parent),
               metrics=list(snakemake.params.metrics), labels=dict(snakemake.params.labels),
               entries=list(snakemake.params.entries), n_resamples=int(snakemake.params.n_resamples),
               seed=int(snakemake.params.seed), manifest_json=snakemake.input.manifest)
else:
    paths = {key: str(value) for key, value in snakemake.output.items()}
    run_logged(snakemake.log[0], write_study_figures_of, snakemake.input.metrics, snakemake.input.timings,
               snakemake.input.recommendations, snakemake.input.scores_ci, list(snakemake.input.renders), paths,
               metric=snakemake.wildcards.metric, entries=list(snakemake.params.entries),
               labels=dict(snakemake.params.labels),
               inputs={name: list(names) for name, names in dict(snakemake.params.inputs).items()})
