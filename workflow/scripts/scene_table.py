from mcbench.pipeline.logs import run_logged
from mcbench.pipeline.report import write_scene_table

run_logged(snakemake.log[0], write_scene_table, snakemake.input.metrics, dict(snakemake.params.references),
           dict(snakemake.params.reference_spp), snakemake.output.csv, snakemake.output.md,
           noisy_records=list(snakemake.input.noisy), reference_records=list(snakemake.input.reference),
           tex_path=snakemake.output.tex)
