from mcbench.pipeline.freed_memory import keep_freed_memory
from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821
keep_freed_memory()  # a network's steps reuse the heap instead of page-faulting fresh memory

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.training import train_learned_method  # noqa: E402

correlated = {name[len("correlated_"):]: list(files) for name, files in snakemake.input.items()
              if name.startswith("correlated_")}
run_logged(snakemake.log[0], train_learned_method, snakemake.wildcards.network, list(snakemake.input.crops),
           snakemake.output.weights, snakemake.output.record, snakemake.params.checkpoint,
           {**snakemake.params.overrides, "threads": snakemake.threads},
           log=lambda message: print(message, flush=True), correlated_files=correlated or None,
           weights_dir=snakemake.params.weights_dir)
