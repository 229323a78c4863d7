# Every case in the layout of the ensemble paper's public program (colorA.exr, colorB.exr,
# albedo.exr, normal.exr, <d>/<d>{,A,B}.exr, plus color, variance, depth and the reference), for
# programs outside the harness: `snakemake --cores 2 export_cases` (not part of `all`).


rule export_case:
    input:
        case=rules.run_case.output.record,
        render=rules.render_noisy.output[0],
        reference=rules.merge_reference.output[0],
    output:
        directory(f"{RESULTS}/export/{{scene}}/spp{{spp}}"),
    params:
        candidates=CANDIDATES,
        candidate_paths=case_outputs,
    threads: 1
    resources:
        **job_resources("export_case"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/export/{{scene}}_spp{{spp}}.log",
    script:
        "../scripts/export_case.py"


rule export_cases:
    localrule: True
    input:
        expand(rules.export_case.output[0], scene=SCENES, spp=SPPS),
