from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

import os  # noqa: E402

os.environ["MCBENCH_WEIGHTS_DIR"] = os.path.abspath(snakemake.params.weights_dir)

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.methods import run_methods  # noqa: E402

run_logged(snakemake.log[0], run_methods, list(snakemake.params.entries), snakemake.input.render,
           scene=snakemake.wildcards.scene, spp=int(snakemake.wildcards.spp), threads=snakemake.threads)
