# Base denoisers and combiners. A base denoiser returns its full and half-buffer results in one
# run; a combiner also reads its input methods' outputs; a learned method also reads its
# weights. Every method writes its own output EXR and a timing record of its compute time.
#
# Jobs (config batch_methods, default true): all methods of a case share one job (rule
# run_case_methods), run in dependency order (denoisers, then combiners in config order), so the
# process starts, imports (torch once) and reads the render and each output once: at 128x128 a
# job's start, imports and reads cost more than most methods' compute, and the default study
# has one job per (scene, spp) case instead of one per method and case. batch_methods false: a
# job per method (rule run_method, e.g. to spread methods over a cluster). `snakemake -f <output
# EXR>` reruns the job that makes it.


rule run_method:
    input:
        render=rules.render_noisy.output[0],
        inputs=method_inputs,
        weights=method_weights,
    output:
        exr=f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.exr",
        timing=f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.json",
    wildcard_constraints:
        method="|".join(SINGLE_JOB_METHODS) or "(?!)",
    params:
        spec=lambda wildcards: METHODS[wildcards.method],
        weights_dir=WEIGHTS_DIR,
        weights_digest=weights_digest,
    threads: 1
    resources:
        **job_resources("run_method"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/methods/{{scene}}_spp{{spp}}_{{method}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/methods/{{scene}}_spp{{spp}}_{{method}}.tsv"
    script:
        "../scripts/run_method.py"


if BATCHES["methods"]:

    rule run_case_methods:
        input:
            render=rules.render_noisy.output[0],
            inputs=batch_inputs("methods"),
            weights=batch_weights("methods"),
        output:
            exr=batch_outputs("methods", "exr"),
            timing=batch_outputs("methods", "timing"),
        params:
            entries=batch_entries("methods"),
            weights_dir=WEIGHTS_DIR,
            weights_digests=batch_weights_digests("methods"),
        threads: 1
        resources:
            **job_resources("run_case_methods"),
        conda:
            "../envs/mcbench.yaml"
        log:
            f"{RESULTS}/logs/methods/{{scene}}_spp{{spp}}_methods.log",
        benchmark:
            f"{RESULTS}/benchmarks/batches/{{scene}}_spp{{spp}}_methods.tsv"
        script:
            "../scripts/run_methods.py"
