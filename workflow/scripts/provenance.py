from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.provenance import write_manifest  # noqa: E402

# rule provenance_manifest of workflow/rules/provenance.smk
run_logged(snakemake.log[0], write_manifest, snakemake.output.json, snakemake.output.md,  # noqa: F821
           repo_dir=snakemake.params.repo_dir, config=dict(snakemake.config))  # noqa: F821
