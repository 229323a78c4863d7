# Every case in the layout of the ensemble paper's public program (colorA.exr, colorB.exr,
# albedo.exr, normal.exr, <d>/<d>{,A,B}.exr, plus color, variance, depth and the reference), for
# programs outside the harness: `snakemake --cores 2 export_cases` (not part of `all`).


rule export_case:
    input:
        case=rules.run_case.output.record,
        render=rules.render_noisy.output[0],
        reference=rules.merge_reference.output[0],
    output:
        directory("results/export/{scene}/spp{spp}"),
    params:
        candidates=list(PLAN.ranking.candidates),
        candidate_paths=get_case_outputs,
        case=get_case_job,  # the outputs the case job removed (keep_outputs: read) are made again
    threads: 1
    resources:
        **STUDY.resources("export_case"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/export/{scene}_spp{spp}.log",
    script:
        "../scripts/export_case.py"


rule export_cases:
    localrule: True
    input:
        expand(rules.export_case.output[0], scene=PLAN.cases.scenes, spp=PLAN.cases.spps),
