from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.export import export_case  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402

candidates = dict(zip(snakemake.params.candidates, snakemake.params.candidate_paths))
run_logged(snakemake.log[0], export_case, snakemake.input.render, candidates, snakemake.output[0],
           reference_path=snakemake.input.reference)
