from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.evaluation import gather_tables  # noqa: E402

cases = [(case["scene"], int(case["spp"])) for case in snakemake.params.cases]
run_logged(snakemake.log[0], gather_tables, list(snakemake.input), snakemake.output[0],
           entries=list(snakemake.params.entries), metric_names=list(snakemake.params.metrics),
           cases=cases)
