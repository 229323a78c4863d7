from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.metrics import compute_case_metrics

candidates = {name: snakemake.input[name] for name in snakemake.params.candidates}
run_logged(snakemake.log[0], compute_case_metrics, snakemake.wildcards.scene, int(snakemake.wildcards.spp),
           snakemake.input.reference, snakemake.input.render, candidates, list(snakemake.params.metrics),
           snakemake.output[0], flip_maps_path=snakemake.output.flip_maps)
