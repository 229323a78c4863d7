from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.viewer import write_viewer_case  # noqa: E402

candidates = {name: snakemake.input[name] for name in snakemake.params.candidates}
run_logged(snakemake.log[0], write_viewer_case, snakemake.wildcards.scene, int(snakemake.wildcards.spp),
           snakemake.input.reference, snakemake.input.render, candidates, snakemake.output[0],
           weight_inputs={name: list(inputs) for name, inputs in snakemake.params.weight_inputs.items()},
           flip_maps_path=snakemake.input.flip_maps)
