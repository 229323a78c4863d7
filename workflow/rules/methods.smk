# Base denoisers and combiners: one job per (scene, spp, method). A base denoiser returns
# its full and half-buffer results in one job; a combiner also reads its input methods'
# outputs; a learned denoiser also reads its weights. Each job writes its output EXR and a
# timing record of its compute time.


rule run_method:
    input:
        render=rules.render_noisy.output[0],
        inputs=method_inputs,
        weights=method_weights,
    output:
        exr=f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.exr",
        timing=f"{RESULTS}/outputs/{{scene}}/spp{{spp}}/{{method}}.json",
    params:
        spec=lambda wildcards: METHODS[wildcards.method],
        weights_dir=WEIGHTS_DIR,
        weights_digest=weights_digest,
    threads: 1
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/methods/{{scene}}_spp{{spp}}_{{method}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/methods/{{scene}}_spp{{spp}}_{{method}}.tsv"
    script:
        "../scripts/run_method.py"
