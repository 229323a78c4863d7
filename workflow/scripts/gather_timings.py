from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.cases import gather_case_timings  # noqa: E402

run_logged(snakemake.log[0], gather_case_timings, list(snakemake.input), snakemake.output[0])
