from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

import os  # noqa: E402

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.progressive_study import write_progressive_tables  # noqa: E402

# rule progressive_tables of workflow/rules/progressive_study.smk
params = snakemake.params
run_logged(snakemake.log[0], write_progressive_tables, snakemake.input.metrics, snakemake.input.timings,
           os.path.dirname(snakemake.output.consistency), pairs=dict(params.pairs),
           labels=dict(params.labels), metrics=list(params.metrics))
