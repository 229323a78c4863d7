from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.metrics import gather_tables

cases = [(case["scene"], int(case["spp"])) for case in snakemake.params.cases]
run_logged(snakemake.log[0], gather_tables, list(snakemake.input), snakemake.output[0],
           candidates=list(snakemake.params.candidates), metric_names=list(snakemake.params.metrics),
           cases=cases)
