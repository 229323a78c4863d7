# Score-and-rank tables (Zheng et al. 2021 Sec. 5.3.3, Table 3 layout).


rule ranking_table:
    localrule: True
    input:
        rules.gather_metrics.output[0],
        scenes="results/tables/scenes.csv",
    output:
        csv=report(
            "results/tables/ranking_{metric}.csv",
            caption="../report/ranking.rst",
            category="Rankings",
            subcategory="Score-and-rank tables",
            labels={"metric": "{metric}", "table": "score and rank per spp"},
        ),
        md="results/tables/ranking_{metric}.md",
        tex="results/tables/ranking_{metric}.tex",
    params:
        metric_label=lambda wildcards: STUDY.metric_labels[wildcards.metric],
        entries=PLAN.ranking.ranked_entries,
        labels=dict(PLAN.ranking.labels),
        order=PLAN.ranking.table_order,
        note=PLAN.ranking.pool_note,
    threads: 1
    resources:
        **STUDY.resources("ranking_table"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/ranking_{metric}.log",
    script:
        "../scripts/ranking_table.py"


# Every method outside the ranking pool, each scored in a pool that adds it alone.
rule extras_table:
    localrule: True
    input:
        rules.gather_metrics.output[0],
        scenes="results/tables/scenes.csv",
    output:
        csv=report(
            "results/tables/extras_{metric}.csv",
            caption="../report/extras.rst",
            category="Extra methods",
            subcategory="Scored alone against the pool",
            labels={"metric": "{metric}", "table": "extra methods, each added alone to the pool"},
        ),
        md="results/tables/extras_{metric}.md",
        tex="results/tables/extras_{metric}.tex",
    params:
        metric_label=lambda wildcards: STUDY.metric_labels[wildcards.metric],
        pool=PLAN.ranking.ranked_entries,
        extras=list(PLAN.ranking.extras),
        labels=dict(PLAN.ranking.labels),
    threads: 1
    resources:
        **STUDY.resources("extras_table"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/extras_{metric}.log",
    script:
        "../scripts/extras_table.py"


rule scene_table:
    localrule: True
    input:
        unpack(get_render_cost_records),
        metrics=rules.gather_metrics.output[0],
        references=list(get_references().values()),
    output:
        csv=report(
            "results/tables/scenes.csv",
            caption="../report/scenes.rst",
            category="Scenes",
            subcategory="Scene table",
            labels={"table": "scenes", "metric": "relmse"},
        ),
        md="results/tables/scenes.md",
        tex="results/tables/scenes.tex",
    params:
        references=get_references(),
        reference_spp=dict(PLAN.cases.reference_spp),
    threads: 1
    resources:
        **STUDY.resources("scene_table"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/scene_table.log",
    script:
        "../scripts/scene_table.py"


rule gallery:
    localrule: True
    input:
        list(get_references().values()),
    output:
        report(
            "results/figures/gallery.png",
            caption="../report/gallery.rst",
            category="Scenes",
            subcategory="Gallery",
            labels={"figure": "references", "scene": "all"},
        ),
    params:
        references=get_references(),
    threads: 1
    resources:
        **STUDY.resources("gallery"),
    conda:
        "../envs/mcbench.yaml"
    log:
        "results/logs/gallery.log",
    script:
        "../scripts/gallery.py"
