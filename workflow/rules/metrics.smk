# Errors of every candidate and of the noisy input against the reference, per test case.


# One job per (scene, spp, entry) (the noisy input and every candidate): its errors and its
# viewer images (a new method is evaluated alone; a changed output re-evaluates only itself), in
# the warm workers of mcbench.pipeline.pool like the methods.
rule evaluate_entry:
    input:
        image=entry_image,
        reference=rules.merge_reference.output[0],
    output:
        metrics=f"{RESULTS}/metrics/{{scene}}/spp{{spp}}/{{entry}}.csv",
        viewer=directory(f"{RESULTS}/viewer_entries/{{scene}}/spp{{spp}}/{{entry}}"),
    wildcard_constraints:
        entry="|".join([NOISY] + CANDIDATES),
    params:
        metrics=METRIC_NAMES,
        weight_inputs=lambda wildcards: METHODS[wildcards.entry]["inputs"] if wildcards.entry in METHODS else [],
    threads: 1
    resources:
        **job_resources("evaluate_entry"),
    log:
        f"{RESULTS}/logs/metrics/{{scene}}/spp{{spp}}/{{entry}}.log",
    run:
        run_in_pool("mcbench.pipeline.metrics:evaluate_entry", wildcards.scene, int(wildcards.spp), wildcards.entry,
                    input.image, input.reference, list(params.metrics), output.metrics, output.viewer, log=log[0],
                    weight_inputs=list(params.weight_inputs))


# A case's errors in one table (its entries' rows, each checked whole).
rule case_metrics:
    input:
        unpack(case_entry_metrics),
    output:
        f"{RESULTS}/metrics/{{scene}}/spp{{spp}}.csv",
    params:
        metrics=METRIC_NAMES,
    threads: 1
    resources:
        **job_resources("case_metrics"),
    log:
        f"{RESULTS}/logs/metrics/{{scene}}_spp{{spp}}.log",
    run:
        run_in_pool("mcbench.pipeline.metrics:assemble_case_metrics", dict(input.items()), output[0],
                    log=log[0], scene=wildcards.scene, spp=int(wildcards.spp), metric_names=list(params.metrics))


# One table of every error; every case must hold every candidate and metric with a finite value
# (mcbench.analysis.ranking.check_complete), or the run stops naming the case file.
rule gather_metrics:
    localrule: True
    input:
        all_case_metrics,
    output:
        report(
            f"{RESULTS}/metrics.csv",
            caption="../report/metrics.rst",
            category="Data",
            subcategory="Errors",
            labels={"table": "metrics.csv", "rows": "scene, spp, candidate, metric"},
        ),
    params:
        candidates=[NOISY] + CANDIDATES,
        metrics=METRIC_NAMES,
        cases=[{"scene": scene, "spp": spp} for scene in SCENES for spp in SPPS],
    threads: 1
    resources:
        **job_resources("gather_metrics"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gather_metrics.log",
    script:
        "../scripts/gather_metrics.py"


rule gather_timings:
    localrule: True
    input:
        all_timing_records,
    output:
        report(
            f"{RESULTS}/timings.csv",
            caption="../report/timings.rst",
            category="Data",
            subcategory="Timings",
            labels={"table": "timings.csv", "rows": "scene, spp, method"},
        ),
    threads: 1
    resources:
        **job_resources("gather_timings"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gather_timings.log",
    script:
        "../scripts/gather_timings.py"
