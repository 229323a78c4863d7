from mcbench.pipeline.threads import limit_threads

limit_threads(snakemake.threads)  # before any heavy import (numba, torch, OpenBLAS, OIDN read it)  # noqa: F821

from mcbench.pipeline.cases import ensure_case_outputs  # noqa: E402
from mcbench.pipeline.export import export_case  # noqa: E402
from mcbench.pipeline.logs import run_logged  # noqa: E402


def export_with_outputs(case, candidates, render, output, *, reference_path, threads):
    ensure_case_outputs(case, list(candidates), threads=threads)
    export_case(render, candidates, output, reference_path=reference_path)


candidates = dict(zip(snakemake.params.candidates, snakemake.params.candidate_paths))  # noqa: F821
run_logged(snakemake.log[0], export_with_outputs, snakemake.params.case, candidates,  # noqa: F821
           snakemake.input.render, snakemake.output[0], reference_path=snakemake.input.reference,  # noqa: F821
           threads=snakemake.threads)  # noqa: F821
