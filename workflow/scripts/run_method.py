import os

os.environ.setdefault("NUMBA_NUM_THREADS", str(snakemake.threads))
os.environ.setdefault("OMP_NUM_THREADS", str(snakemake.threads))          # PyTorch's intra-op threads
os.environ["MCBENCH_WEIGHTS_DIR"] = os.path.abspath(snakemake.params.weights_dir)

from mcbench.pipeline.logs import run_logged  # noqa: E402
from mcbench.pipeline.methods import run_method  # noqa: E402

spec = snakemake.params.spec
run_logged(snakemake.log[0], run_method, snakemake.wildcards.method, snakemake.input.render,
           snakemake.output.exr, snakemake.output.timing, module_name=spec["module"],
           params=spec["params"], input_paths=list(snakemake.input.inputs),
           scene=snakemake.wildcards.scene, spp=int(snakemake.wildcards.spp), threads=snakemake.threads)
