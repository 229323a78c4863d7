# Score-and-rank tables (Zheng et al. 2021 Sec. 5.3.3, Table 3 layout).


rule ranking_table:
    input:
        f"{RESULTS}/metrics.csv",
    output:
        csv=report(
            f"{RESULTS}/tables/ranking_{{metric}}.csv",
            caption="../report/ranking.rst",
            category="Ranking",
        ),
        md=f"{RESULTS}/tables/ranking_{{metric}}.md",
    params:
        order=["noisy"] + CANDIDATES,
        labels=LABELS,
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/ranking_{{metric}}.log",
    script:
        "../scripts/ranking_table.py"


rule scene_table:
    input:
        metrics=f"{RESULTS}/metrics.csv",
        references=[reference_path(scene) for scene in SCENES],
    output:
        csv=report(f"{RESULTS}/tables/scenes.csv", caption="../report/scenes.rst", category="Scenes"),
        md=f"{RESULTS}/tables/scenes.md",
    params:
        references={scene: reference_path(scene) for scene in SCENES},
        reference_spp=REFERENCE_SPP,
        benchmarks=f"{RESULTS}/benchmarks",
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/scene_table.log",
    script:
        "../scripts/scene_table.py"


rule gallery:
    input:
        [reference_path(scene) for scene in SCENES],
    output:
        report(f"{RESULTS}/figures/gallery.png", caption="../report/gallery.rst", category="Scenes"),
    params:
        references={scene: reference_path(scene) for scene in SCENES},
    conda:
        "../envs/mcbench.yaml"
    log:
        f"{RESULTS}/logs/gallery.log",
    script:
        "../scripts/gallery.py"
