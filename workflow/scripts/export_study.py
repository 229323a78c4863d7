from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # noqa: F821

from pathlib import Path  # noqa: E402

from mcbench.pipeline.bundle import export_study  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402

# rule export_study of workflow/rules/bundle.smk: the working folder's results/ (Snakemake runs the
# script there); the checkout: two folders above this script's folder (scriptdir may read
# workflow/rules/../scripts: resolved first)
run_logged(snakemake.log[0], export_study, "results", snakemake.output[0],  # noqa: F821
           config=dict(snakemake.config), workdir=".",  # noqa: F821
           checkout_dir=str(Path(snakemake.scriptdir).resolve().parents[1]))  # noqa: F821
