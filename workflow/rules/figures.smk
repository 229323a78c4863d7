# Figures of the report (mcbench.analysis.error_speed_figures): error against spp per scene for each metric, and
# each method's speed against its error.

# The speed figure's metric: PLAN.ranking.speed_metric; the curves' lines: STUDY.curve_entries.


rule error_curves:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
    output:
        report(
            "results/figures/error_{metric}.png",
            caption="../report/error_curves.rst",
            category="Figures",
            subcategory="Error against spp",
            labels={"metric": "{metric}", "figure": "error against spp, per scene"},
        ),
    params:
        metric_label=lambda wildcards: STUDY.metric_labels[wildcards.metric],
        labels=dict(PLAN.ranking.labels),
        entries=STUDY.curve_entries,
    threads: 1
    resources:
        **STUDY.resources("error_curves"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/figures/error_{metric}.log",
    script:
        "../scripts/error_curves.py"


rule speed_error:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
    output:
        report(
            "results/figures/speed_error.png",
            caption="../report/speed_error.rst",
            category="Figures",
            subcategory="Speed against error",
            labels={"metric": PLAN.ranking.speed_metric, "figure": "speed against error"},
        ),
    params:
        metric_label=STUDY.metric_labels[PLAN.ranking.speed_metric],
        labels=dict(PLAN.ranking.labels),
        inputs=PLAN.method_inputs,
        metric=PLAN.ranking.speed_metric,
    threads: 1
    resources:
        **STUDY.resources("speed_error"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/figures/speed_error.log",
    script:
        "../scripts/speed_error.py"
