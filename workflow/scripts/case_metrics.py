from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.metrics import compute_case_metrics  # noqa: E402

candidates = {name: snakemake.input[name] for name in snakemake.params.candidates}
run_logged(snakemake.log[0], compute_case_metrics, snakemake.wildcards.scene, int(snakemake.wildcards.spp),
           snakemake.input.reference, snakemake.input.render, candidates, list(snakemake.params.metrics),
           snakemake.output[0], flip_maps_path=snakemake.output.flip_maps)
