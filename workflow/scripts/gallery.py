from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.rankings import write_gallery  # noqa: E402

run_logged(snakemake.log[0], write_gallery, dict(snakemake.params.references), snakemake.output[0])
