from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.viewer import write_viewer

cases = [(case["scene"], int(case["spp"])) for case in snakemake.params.cases]
run_logged(snakemake.log[0], write_viewer, snakemake.input.metrics, list(snakemake.input.cases), snakemake.output[0],
           cases=cases, candidates=list(snakemake.params.candidates), labels=dict(snakemake.params.labels),
           metric_names=list(snakemake.params.metrics), static_dir=snakemake.params.static_dir)
