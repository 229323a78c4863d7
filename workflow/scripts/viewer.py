from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.viewer import write_viewer  # noqa: E402

cases = [(case["scene"], int(case["spp"])) for case in snakemake.params.cases]
run_logged(snakemake.log[0], write_viewer, snakemake.input.metrics, list(snakemake.input.cases), snakemake.output[0],
           cases=cases, candidates=list(snakemake.params.candidates), labels=dict(snakemake.params.labels),
           metric_names=list(snakemake.params.metrics), static_dir=snakemake.params.static_dir)
