# Errors of every candidate and of the noisy input against the reference, per test case.


# Each entry of a case (the noisy input and every candidate) is evaluated into two files: its
# errors (metrics/<scene>/spp<N>/<metric set>/<entry>.csv; the folder names the metric list, so a
# new metric list is new files) and its viewer images (viewer_entries/<scene>/spp<N>/<entry>/).
# As for the methods: an existing file belongs to entry_metrics or entry_viewer (rerun when
# Snakemake finds it out of date), the missing ones to one batch job per case; one definition,
# in the warm workers of mcbench.pipeline.pool.
for job in EVAL_JOBS:

    rule:
        name:
            job["rule"]
        input:
            images=job["images"],
            reference=rules.merge_reference.output[0],
        output:
            **job["outputs"],
        wildcard_constraints:
            **job["constraints"],
        threads: 1
        resources:
            **job_resources("evaluate_entry", batch=job["batch"]),
        log:
            job["log"],
        run:
            run_in_pool("mcbench.pipeline.metrics:evaluate_entries", evaluation_items(rule, wildcards), input.reference,
                        log=log[0], scene=wildcards.scene, spp=int(wildcards.spp), metrics=METRIC_NAMES)

    if job["items"]:  # a missing file: its batch, not the per-file rules
        workflow.ruleorder(job["rule"], "entry_metrics")
        workflow.ruleorder(job["rule"], "entry_viewer")


# A case's errors in one table (its entries' rows, each checked whole).
rule case_metrics:
    input:
        case_entry_metrics,
    output:
        f"{RESULTS}/metrics/{{scene}}/spp{{spp}}.csv",
    params:
        metrics=METRIC_NAMES,
        entries=ENTRIES,
    threads: 1
    resources:
        **job_resources("case_metrics"),
    log:
        f"{RESULTS}/logs/metrics/{{scene}}_spp{{spp}}.log",
    run:
        run_case_assembly("mcbench.pipeline.metrics:assemble_case_metrics", input, output, params, wildcards, log,
                          metric_names=list(params.metrics))


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
    params:
        candidates=CANDIDATES,
        cases=[{"scene": scene, "spp": spp} for scene in SCENES for spp in SPPS],
    threads: 1
    resources:
        **job_resources("gather_timings"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gather_timings.log",
    script:
        "../scripts/gather_timings.py"
