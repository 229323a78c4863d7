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
    wildcard_constraints:
        scene=STUDY.merged_scene_pattern,
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


# A reference from the reference store (reference.source: store, mcbench.pipeline.reference_sources):
# read and checked against its record, then tested against this run's highest-spp render before a
# case uses it (check_reference); `snakemake --cores 2 store_references` fills the store from this
# config's reference settings: the references this run renders, stored from their merge (a finished
# run's are not rendered again), and a scene the store already holds rendered afresh.


rule stored_reference:
    input:
        get_reference_inputs,
    output:
        "results/references/{scene}.exr",
    wildcard_constraints:
        scene=STUDY.stored_scene_pattern,
    params:
        record=lambda wildcards: PLAN.cases.stored_references[wildcards.scene],
    threads: 1
    resources:
        **STUDY.resources("merge_reference"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/stored_reference/{scene}.log",
    script:
        "../scripts/stored_reference.py"


rule check_reference:
    input:
        reference="results/references/{scene}.exr",
        render=get_checked_render,
    output:
        "results/references/{scene}.check.json",
    threads: 1
    resources:
        **STUDY.resources("merge_reference"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/check_reference/{scene}.log",
    script:
        "../scripts/check_reference.py"


rule store_reference:
    input:
        get_store_inputs,
    output:
        f"{STUDY.store_folder}/{{resolution}}/{{scene}}.json",
    params:
        features=config["features"],
    threads: 1
    resources:
        **STUDY.resources("merge_reference"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/store_reference/{scene}_{resolution}.log",
    script:
        "../scripts/store_reference.py"


rule store_references:
    input:
        get_store_records,
    localrule: True
