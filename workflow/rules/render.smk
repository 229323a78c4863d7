# Rendering: noisy full/half buffers per (scene, spp) and chunked high-spp references; a scene of
# renders made elsewhere (scenes/<name>.yaml) has its cases and reference imported instead.


rule render_noisy:
    input:
        imported_case_files,
    output:
        f"{RESULTS}/renders/{{scene}}/spp{{spp}}.exr",
    params:
        resolution=config["resolution"],
        variant=config["variant"],
        **feature_params(),
        seed=config["seed"],
    threads: config["render_threads"]
    resources:
        **job_resources("render_noisy"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/render_noisy/{{scene}}_spp{{spp}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/render_noisy/{{scene}}_spp{{spp}}.tsv"
    script:
        "../scripts/render_noisy.py"


rule render_reference_chunk:
    output:
        temp(f"{RESULTS}/references/{{scene}}/chunk{{chunk}}.exr"),
    params:
        spp=reference_chunk_spp,
        resolution=config["resolution"],
        variant=config["variant"],
        **feature_params(),
        seed=config["seed"],
    threads: config["render_threads"]
    resources:
        **job_resources("render_reference_chunk"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/render_reference/{{scene}}_chunk{{chunk}}.log",
    benchmark:
        f"{RESULTS}/benchmarks/render_reference/{{scene}}_chunk{{chunk}}.tsv"
    script:
        "../scripts/render_reference_chunk.py"


rule merge_reference:
    input:
        reference_inputs,
    output:
        f"{RESULTS}/references/{{scene}}.exr",
    params:
        chunks=REFERENCE_CHUNKS,
        spp=lambda wildcards: REFERENCE_SPP[wildcards.scene],
        folder=lambda wildcards: str(RENDER_FOLDERS.get(wildcards.scene) or ""),
    threads: 1
    resources:
        **job_resources("merge_reference"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/merge_reference/{{scene}}.log",
    script:
        "../scripts/merge_reference.py"
