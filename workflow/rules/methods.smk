# Base denoisers and combiners: one job per (scene, spp, method), so Snakemake decides method by
# method what an edit of the config makes out of date (a new method runs alone; changed params
# rerun the method and the combiners that read it). A base denoiser returns its full and
# half-buffer results in one run; a combiner also reads its input methods' outputs; a learned
# method also reads its weights. Every method writes its own output EXR and a timing record of
# its compute time.
#
# The jobs are small (tens of milliseconds of compute at 128x128), so they run in warm worker
# processes that import once (mcbench.pipeline.pool; rule `run:` blocks in Snakemake's process,
# common.smk's run_in_pool), not in a process each. `snakemake -f <output EXR>` reruns one.


rule run_method:
    input:
        render=rules.render_noisy.output[0],
        inputs=method_inputs,
        weights=method_weights,
    output:
        exr=f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.exr",
        timing=f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.json",
    wildcard_constraints:
        method="|".join(METHODS) or "(?!)",
    params:
        spec=lambda wildcards: METHODS[wildcards.method],
        weights_dir=WEIGHTS_DIR,
        weights_digest=weights_digest,
    threads: 1
    resources:
        **job_resources("run_method"),
    log:
        f"{RESULTS}/logs/methods/{{scene}}/spp{{spp}}/{{method}}.log",
    run:
        run_in_pool("mcbench.pipeline.methods:run_method", wildcards.method, input.render, output.exr,
                    output.timing, log=log[0], module_name=params.spec["module"], params=params.spec["params"],
                    input_paths=list(input.inputs), scene=wildcards.scene, spp=int(wildcards.spp), threads=threads)
