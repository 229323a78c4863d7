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
