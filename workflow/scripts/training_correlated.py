from mcbench.pipeline.freed_memory import keep_freed_memory
from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821
keep_freed_memory()  # a network's steps reuse the heap instead of page-faulting fresh memory

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.training import write_correlated_training_inputs  # noqa: E402

run_logged(snakemake.log[0], write_correlated_training_inputs, snakemake.wildcards.base, list(snakemake.input.crops),
           list(snakemake.output), weights_dir=snakemake.params.weights_dir, threads=snakemake.threads)
