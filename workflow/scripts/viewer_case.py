from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.viewer import write_viewer_case

candidates = {name: snakemake.input[name] for name in snakemake.params.candidates}
run_logged(snakemake.log[0], write_viewer_case, snakemake.wildcards.scene, int(snakemake.wildcards.spp),
           snakemake.input.reference, snakemake.input.render, candidates, snakemake.output[0],
           weight_inputs={name: list(inputs) for name, inputs in snakemake.params.weight_inputs.items()},
           flip_maps_path=snakemake.input.flip_maps)
