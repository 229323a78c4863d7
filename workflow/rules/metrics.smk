# Errors of every entry (the noisy input and every candidate) against the reference, gathered from the
# cases' tables (rule run_case, methods.smk), and the methods' timings from the cases' records.


# One table of every error; every case must hold every entry and metric with a finite value
# (mcbench.analysis.ranking.check_complete), or the run stops naming the case file.
rule gather_metrics:
    localrule: True
    input:
        get_case_files("metrics"),
    output:
        report(
            "results/metrics.csv",
            caption="../report/metrics.rst",
            category="Data",
            subcategory="Errors",
            labels={"table": "metrics.csv", "rows": "scene, spp, entry, metric"},
        ),
    params:
        entries=PLAN.ranking.entries,
        metrics=list(PLAN.ranking.metrics),
        cases=PLAN.cases.case_list,
    threads: 1
    resources:
        **STUDY.resources("gather_metrics"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/gather_metrics.log",
    script:
        "../scripts/gather_metrics.py"


rule gather_timings:
    localrule: True
    input:
        get_case_files("record"),
    output:
        report(
            "results/timings.csv",
            caption="../report/timings.rst",
            category="Data",
            subcategory="Timings",
            labels={"table": "timings.csv", "rows": "scene, spp, method"},
        ),
    params:
        candidates=list(PLAN.ranking.candidates),
        cases=PLAN.cases.case_list,
    threads: 1
    resources:
        **STUDY.resources("gather_timings"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/gather_timings.log",
    script:
        "../scripts/gather_timings.py"
