# The comparisons of Zheng et al. 2021 Sec. 5.2 (mcbench.analysis.comparison_tables): Tables 1-2 (ensemble
# against one-hot selection), the ablation table and the comparison methods' own ranking.
# Which method compares with which is read from the method table (module docstring).



rule comparison_onehot:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
    output:
        table1_csv=report(
            "results/tables/comparisons/table1_{metric}.csv",
            caption="../report/comparisons_onehot.rst",
            category="Comparisons",
            subcategory="Tables 1-2: one-hot selection",
            labels={"metric": "{metric}", "table": "Table 1 (pre-filtering SBF, NFOR)"},
        ),
        table1_md="results/tables/comparisons/table1_{metric}.md",
        table2_csv=report(
            "results/tables/comparisons/table2_{metric}.csv",
            caption="../report/comparisons_onehot.rst",
            category="Comparisons",
            subcategory="Tables 1-2: one-hot selection",
            labels={"metric": "{metric}", "table": "Table 2 (post-filtering)"},
        ),
        table2_md="results/tables/comparisons/table2_{metric}.md",
    params:
        metric_label=lambda wildcards: STUDY.metric_labels[wildcards.metric],
        methods=PLAN.comparison_methods,
        labels=dict(PLAN.ranking.labels),
    threads: 1
    resources:
        **STUDY.resources("comparison_onehot"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/comparison_onehot_{metric}.log",
    script:
        "../scripts/comparison_onehot.py"


rule comparison_ablations:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
        timings=rules.gather_timings.output[0],
    output:
        csv=report(
            "results/tables/comparisons/ablations.csv",
            caption="../report/comparisons_ablations.rst",
            category="Comparisons",
            subcategory="Ablations",
            labels={"table": "ablations", "metric": "relmse, dssim"},
        ),
        md="results/tables/comparisons/ablations.md",
    params:
        methods=PLAN.comparison_methods,
        labels=dict(PLAN.ranking.labels),
    threads: 1
    resources:
        **STUDY.resources("comparison_ablations"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/comparison_ablations.log",
    script:
        "../scripts/comparison_ablations.py"


rule comparison_ranking:
    localrule: True
    input:
        metrics=rules.gather_metrics.output[0],
    output:
        csv=report(
            "results/tables/comparisons/ranking_{metric}.csv",
            caption="../report/comparisons_ranking.rst",
            category="Comparisons",
            subcategory="Comparison rankings",
            labels={"metric": "{metric}", "table": "comparison methods beside their ensembles"},
        ),
        md="results/tables/comparisons/ranking_{metric}.md",
    params:
        metric_label=lambda wildcards: STUDY.metric_labels[wildcards.metric],
        methods=PLAN.comparison_methods,
        labels=dict(PLAN.ranking.labels),
    threads: 1
    resources:
        **STUDY.resources("comparison_ranking"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/comparison_ranking_{metric}.log",
    script:
        "../scripts/comparison_ranking.py"
