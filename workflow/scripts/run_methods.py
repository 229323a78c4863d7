import os

os.environ.setdefault("NUMBA_NUM_THREADS", str(snakemake.threads))
os.environ.setdefault("OMP_NUM_THREADS", str(snakemake.threads))          # PyTorch's intra-op threads
os.environ["MCBENCH_WEIGHTS_DIR"] = os.path.abspath(snakemake.params.weights_dir)

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.methods import run_methods  # noqa: E402

run_logged(snakemake.log[0], run_methods, list(snakemake.params.entries), snakemake.input.render,
           scene=snakemake.wildcards.scene, spp=int(snakemake.wildcards.spp), threads=snakemake.threads)
