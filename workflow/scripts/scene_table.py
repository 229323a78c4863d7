from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.rankings import write_scene_table  # noqa: E402

run_logged(snakemake.log[0], write_scene_table, snakemake.input.metrics, dict(snakemake.params.references),
           dict(snakemake.params.reference_spp), snakemake.output.csv, snakemake.output.md,
           noisy_records=list(snakemake.input.noisy), reference_records=list(snakemake.input.reference),
           tex_path=snakemake.output.tex)
