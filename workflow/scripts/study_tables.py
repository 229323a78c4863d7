from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from pathlib import Path  # noqa: E402

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.pool_study import write_study  # noqa: E402

# rule study_tables of workflow/rules/study.smk
run_logged(snakemake.log[0], write_study, snakemake.input.metrics, str(Path(snakemake.output.summary).parent),
           metrics=list(snakemake.params.metrics), labels=dict(snakemake.params.labels),
           entries=list(snakemake.params.entries), n_resamples=int(snakemake.params.n_resamples),
           seed=int(snakemake.params.seed), manifest_json=snakemake.input.manifest)
