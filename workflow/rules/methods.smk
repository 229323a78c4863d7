# Base denoisers and combiners. A base denoiser returns its full and half-buffer results in one
# run; a combiner also reads its input methods' outputs; a learned method also reads its
# weights. Every method writes its own output EXR and a timing record of its compute time.
#
# Jobs (config batch_methods, default true): each non-learned base denoiser gets a job per case
# (rule run_method); the learned denoisers of a case share one job (torch is imported once) and
# the combiners of a case share another, run in config order (rules run_learned_denoisers,
# run_combiners): at 128x128 a job's process start, imports and EXR reads cost more than an
# ensemble's compute. `snakemake -f <output EXR>` reruns the job that makes it.


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


if BATCHES["learned_denoisers"]:

    rule run_learned_denoisers:
        input:
            render=rules.render_noisy.output[0],
            weights=batch_weights("learned_denoisers"),
        output:
            exr=batch_outputs("learned_denoisers", "exr"),
            timing=batch_outputs("learned_denoisers", "timing"),
        params:
            entries=batch_entries("learned_denoisers"),
            weights_dir=WEIGHTS_DIR,
            weights_digests=batch_weights_digests("learned_denoisers"),
        threads: 1
        resources:
            **job_resources("run_learned_denoisers"),
        conda:
            "../envs/mcbench.yaml"
        log:
            f"{RESULTS}/logs/methods/{{scene}}_spp{{spp}}_learned_denoisers.log",
        benchmark:
            f"{RESULTS}/benchmarks/batches/{{scene}}_spp{{spp}}_learned_denoisers.tsv"
        script:
            "../scripts/run_methods.py"


if BATCHES["combiners"]:

    rule run_combiners:
        input:
            render=rules.render_noisy.output[0],
            inputs=batch_inputs("combiners"),
            weights=batch_weights("combiners"),
        output:
            exr=batch_outputs("combiners", "exr"),
            timing=batch_outputs("combiners", "timing"),
        params:
            entries=batch_entries("combiners"),
            weights_dir=WEIGHTS_DIR,
            weights_digests=batch_weights_digests("combiners"),
        threads: 1
        resources:
            **job_resources("run_combiners"),
        conda:
            "../envs/mcbench.yaml"
        log:
            f"{RESULTS}/logs/methods/{{scene}}_spp{{spp}}_combiners.log",
        benchmark:
            f"{RESULTS}/benchmarks/batches/{{scene}}_spp{{spp}}_combiners.tsv"
        script:
            "../scripts/run_methods.py"
