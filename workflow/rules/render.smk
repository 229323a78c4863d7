# Rendering: noisy full/half buffers per (scene, spp) and chunked high-spp references; a scene of
# renders made elsewhere (scenes/<name>.yaml) has its cases and reference imported instead.


rule render_noisy:
    input:
        get_imported_case_files,
    output:
        "results/renders/{scene}/spp{spp}.exr",
    params:
        resolution=config["resolution"],
        variant=config["variant"],
        **STUDY.feature_params,
        seed=config["seed"],
    threads: config["render_threads"]
    resources:
        **STUDY.resources("render_noisy"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/render_noisy/{scene}_spp{spp}.log",
    benchmark:
        "results/benchmarks/render_noisy/{scene}_spp{spp}.tsv"
    script:
        "../scripts/render_noisy.py"


rule render_reference_chunk:
    output:
        temp("results/references/{scene}/chunk{chunk}.exr"),
    params:
        spp=lambda wildcards: PLAN.cases.chunk_spp(wildcards.scene),
        resolution=config["resolution"],
        variant=config["variant"],
        **STUDY.feature_params,
        seed=config["seed"],
    threads: config["render_threads"]
    resources:
        **STUDY.resources("render_reference_chunk"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/render_reference/{scene}_chunk{chunk}.log",
    benchmark:
        "results/benchmarks/render_reference/{scene}_chunk{chunk}.tsv"
    script:
        "../scripts/render_reference_chunk.py"


rule merge_reference:
    input:
        get_reference_inputs,
    output:
        "results/references/{scene}.exr",
    params:
        chunks=PLAN.cases.reference_chunks,
        spp=lambda wildcards: PLAN.cases.reference_spp[wildcards.scene],
        folder=lambda wildcards: str(PLAN.cases.render_folders.get(wildcards.scene) or ""),
    threads: 1
    resources:
        **STUDY.resources("merge_reference"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/merge_reference/{scene}.log",
    script:
        "../scripts/merge_reference.py"
