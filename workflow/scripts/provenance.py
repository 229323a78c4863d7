from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from pathlib import Path  # noqa: E402

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.provenance import write_manifest  # noqa: E402

# rule provenance_manifest of workflow/rules/provenance.smk; the checkout: two folders above this
# script's source (workflow/scripts/), the checkout whose Snakefile ran
run_logged(snakemake.log[0], write_manifest, snakemake.output.json, snakemake.output.md,  # noqa: F821
           repo_dir=str(Path(snakemake.scriptdir).parents[1]), config=dict(snakemake.config),  # noqa: F821
           references=list(snakemake.input.references))  # noqa: F821
