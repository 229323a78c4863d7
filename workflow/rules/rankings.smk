# Score-and-rank tables (Zheng et al. 2021 Sec. 5.3.3, Table 3 layout).


rule ranking_table:
    localrule: True
    input:
        rules.gather_metrics.output[0],
        scenes=f"{RESULTS}/tables/scenes.csv",
    output:
        csv=report(
            f"{RESULTS}/tables/ranking_{{metric}}.csv",
            caption="../report/ranking.rst",
            category="Rankings",
            subcategory="Score-and-rank tables",
            labels={"metric": "{metric}", "table": "score and rank per spp"},
        ),
        md=f"{RESULTS}/tables/ranking_{{metric}}.md",
        tex=f"{RESULTS}/tables/ranking_{{metric}}.tex",
    params:
        entries=[NOISY] + RANKED,
        labels=LABELS,
        order=RANKED + [NOISY] if POOL_STUDY else None,
        note=POOL_NOTE,
    threads: 1
    resources:
        **job_resources("ranking_table"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/ranking_{{metric}}.log",
    script:
        "../scripts/ranking_table.py"


# Every method outside the ranking pool, each scored in a pool that adds it alone.
rule extras_table:
    localrule: True
    input:
        rules.gather_metrics.output[0],
        scenes=f"{RESULTS}/tables/scenes.csv",
    output:
        csv=report(
            f"{RESULTS}/tables/extras_{{metric}}.csv",
            caption="../report/extras.rst",
            category="Extra methods",
            subcategory="Scored alone against the pool",
            labels={"metric": "{metric}", "table": "extra methods, each added alone to the pool"},
        ),
        md=f"{RESULTS}/tables/extras_{{metric}}.md",
        tex=f"{RESULTS}/tables/extras_{{metric}}.tex",
    params:
        pool=[NOISY] + RANKED,
        extras=EXTRAS,
        labels=LABELS,
    threads: 1
    resources:
        **job_resources("extras_table"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/extras_{{metric}}.log",
    script:
        "../scripts/ranking_table.py"


rule scene_table:
    localrule: True
    input:
        unpack(render_cost_records),
        metrics=rules.gather_metrics.output[0],
        references=list(reference_paths().values()),
    output:
        csv=report(
            f"{RESULTS}/tables/scenes.csv",
            caption="../report/scenes.rst",
            category="Scenes",
            subcategory="Scene table",
            labels={"table": "scenes", "metric": "relmse"},
        ),
        md=f"{RESULTS}/tables/scenes.md",
        tex=f"{RESULTS}/tables/scenes.tex",
    params:
        references=reference_paths(),
        reference_spp=REFERENCE_SPP,
    threads: 1
    resources:
        **job_resources("scene_table"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/scene_table.log",
    script:
        "../scripts/scene_table.py"


rule gallery:
    localrule: True
    input:
        list(reference_paths().values()),
    output:
        report(
            f"{RESULTS}/figures/gallery.png",
            caption="../report/gallery.rst",
            category="Scenes",
            subcategory="Gallery",
            labels={"figure": "references", "scene": "all"},
        ),
    params:
        references=reference_paths(),
    threads: 1
    resources:
        **job_resources("gallery"),
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gallery.log",
    script:
        "../scripts/gallery.py"
